"""Fresh open + decode_all (one thread) of the posed captures' 40 dB files, this checkout against an
older one (PYTHONPATH), fresh processes interleaved, ROUNDS rounds, median s. Args: OLD ROUNDS NAME..."""
import json, os, statistics, subprocess, sys
W = "import sys,time,json;from formats.lfcfile import open_lfc;from rlfc import RlfcDecoder;" \
    "RlfcDecoder(open_lfc(sys.argv[1])).decode_block(0,0,0,0);t=time.perf_counter();" \
    "RlfcDecoder(open_lfc(sys.argv[1])).decode_all(threads=1);print(json.dumps(time.perf_counter()-t))"
here = os.path.abspath(os.path.join(os.path.dirname(__file__), "../../../.."))
old, rounds, names = sys.argv[1], int(sys.argv[2]), sys.argv[3:]
res = {}
for r in range(rounds):
    for n in names:
        for ver, code in ((("new", here), ("old", old)) if r % 2 == 0 else (("old", old), ("new", here))):
            out = subprocess.run([sys.executable, "-c", W, f"/tmp/dec/{n}.lfc"], capture_output=True, text=True, cwd="/tmp",
                                 env=dict(os.environ, PYTHONPATH=code, OMP_NUM_THREADS="1"))
            res.setdefault((n, ver), []).append(json.loads(out.stdout.splitlines()[-1]))
for n in names:
    a, b = statistics.median(res[(n, "old")]), statistics.median(res[(n, "new")])
    print(f"{n:24s} fresh open + decode_all: old {a:.3f} s new {b:.3f} s x{b / a:.3f}")
