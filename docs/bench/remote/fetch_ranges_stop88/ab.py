"""tools.bench_remote's numbers (20 ms latency, 64 KiB pages) for two checkouts, fresh processes
alternated: OLD=... NEW=... python ab.py ROUNDS FILE..."""
import json, os, subprocess, sys, statistics
rounds, files = int(sys.argv[1]), sys.argv[2:]
vers = {"new": os.environ["NEW"], "old": os.environ["OLD"]}
keys = ("open_s", "open_and_first_frame_s", "frame_requests_first", "frame_ms_p50", "frame_requests_mean",
        "first_block_s", "block_requests_mean", "render_wire_bytes")
res = {}
for r in range(rounds):
    for f in files:
        for v, code in (vers.items() if r % 2 == 0 else reversed(list(vers.items()))):
            o = subprocess.run([sys.executable, "-m", "tools.bench_remote", f, "--latency-ms", "20", "--blocks", "20",
                                "--frames", "8"], env=dict(os.environ, PYTHONPATH=code, OMP_NUM_THREADS="1"),
                               capture_output=True, text=True, cwd=code)
            out = o.stdout + o.stderr
            d = json.loads(out[out.index("{"):])
            for k in keys:
                res.setdefault((f, v, k), []).append(d[k])
for f in files:
    for k in keys:
        a, b = statistics.median(res[(f, "old", k)]), statistics.median(res[(f, "new", k)])
        print(f"{os.path.basename(f):30s} {k:24s} old {a:10.3f} new {b:10.3f}  x{(b / a if a else float('nan')):.3f}")
