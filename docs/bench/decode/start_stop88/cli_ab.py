import subprocess, sys, os, statistics, time
rounds = int(sys.argv[1])
cmds = {
 "info": ["info", "/tmp/dec/stanford_chess.lfc"],
 "decode --block": ["decode", "/tmp/dec/stanford_chess.lfc", "/tmp/w88/blk.png", "--block", "3,4,2,2"],
 "render": ["render", "/tmp/dec/stanford_chess.lfc", "/tmp/w88/fr.png", "--at", "3,4.2", "--quiet"],
}
vers = {"new": os.environ["NEW"], "old": os.environ["OLD"]}   # two checkouts, both compiled (python -m compileall): the shell here sets PYTHONDONTWRITEBYTECODE
res = {}
for r in range(rounds):
    for name, c in cmds.items():
        for v, code in (vers.items() if r % 2 == 0 else reversed(list(vers.items()))):
            env = dict(os.environ, PYTHONPATH=code, OMP_NUM_THREADS="1")
            for f in ("/tmp/w88/blk.png", "/tmp/w88/fr.png"):
                if os.path.exists(f): os.remove(f)
            t = time.perf_counter()
            o = subprocess.run([sys.executable, "-m", "formats.cli"] + c, env=env, capture_output=True, text=True, cwd="/tmp")
            res.setdefault((name, v), []).append(time.perf_counter() - t)
            assert o.returncode == 0, o.stderr
for name in cmds:
    a, b = statistics.median(res[(name, "old")]), statistics.median(res[(name, "new")])
    print(f"lfcodec {name:16s} old {a*1e3:6.0f} ms new {b*1e3:6.0f} ms  x{b/a:.3f}")
