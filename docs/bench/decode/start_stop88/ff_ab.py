import subprocess, json, sys, os, statistics
files, rounds = sys.argv[2:], int(sys.argv[1])
vers = {"new": "/work/main", "old": "/tmp/old88"}   # (the first frame is timed after the imports: no .pyc bias)
res = {}
for r in range(rounds):
    for f in files:
        for v, code in (vers.items() if r % 2 == 0 else reversed(list(vers.items()))):
            env = dict(os.environ, PYTHONPATH=code, OMP_NUM_THREADS="1")
            o = subprocess.run([sys.executable, "/work/main/docs/bench/decode/mag_steps_stop87/ffw.py", f"/tmp/dec/{f}.lfc"], env=env, capture_output=True, text=True, cwd="/tmp")
            d = json.loads(o.stdout.splitlines()[-1])
            for k, x in d.items():
                res.setdefault((f, k, v), []).append(x)
for f in files:
    for k in ("first_frame_ms",):
        a, b = statistics.median(res[(f, k, "old")]), statistics.median(res[(f, k, "new")])
        print(f"{f:28s} {k:16s} old {a:7.1f} new {b:7.1f}  x{b/a:.3f}", flush=True)
