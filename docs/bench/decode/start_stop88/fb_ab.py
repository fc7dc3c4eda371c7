import subprocess, sys, os, statistics
files, rounds = sys.argv[2:], int(sys.argv[1])
vers = {"new": os.environ["NEW"], "old": os.environ["OLD"]}   # two checkouts, both compiled (python -m compileall): the shell here sets PYTHONDONTWRITEBYTECODE
res = {}
for r in range(rounds):
    for f in files:
        for v, code in (vers.items() if r % 2 == 0 else reversed(list(vers.items()))):
            env = dict(os.environ, PYTHONPATH=code, OMP_NUM_THREADS="1")
            o = subprocess.run([sys.executable, "/work/main/docs/bench/decode/start_stop88/first_block.py", f"/tmp/dec/{f}.lfc"], env=env, capture_output=True, text=True, cwd="/tmp")
            a, b = map(float, o.stdout.split())
            res.setdefault((f, v), []).append((a, b))
for f in files:
    o, n = res[(f, "old")], res[(f, "new")]
    for i, k in enumerate(("import+open", "…+first block")):
        a, b = statistics.median(x[i] for x in o), statistics.median(x[i] for x in n)
        print(f"{f:28s} {k:14s} old {a:6.1f} new {b:6.1f} ms x{b/a:.3f}")
