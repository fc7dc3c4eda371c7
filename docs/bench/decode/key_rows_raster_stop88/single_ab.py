"""Single decode_block latency from a fresh decoder (first touches of key rows included), with
KEY_ROWS_RASTER_MIN 1 (raster) and 10**9 (blocks) (named KEY_ROWS_RASTER True/False when these ran), alternated in one process: p50/p90 µs of N random requests."""
import os, sys, time, numpy as np
from formats.lfcfile import open_lfc
from rlfc import RlfcDecoder
import rlfc.profiles.tx_lazy as tl
rounds, N = int(sys.argv[1]), int(sys.argv[2])
for g in sys.argv[3:]:
    path = f"/tmp/dec/{g}.lfc"
    RlfcDecoder(open_lfc(path)).decode_block(0, 0, 0, 0)
    res = {False: [], True: []}
    for r in range(rounds):
        rng = np.random.default_rng(r)
        d0 = RlfcDecoder(open_lfc(path))
        req = [(int(rng.integers(d0.rows)), int(rng.integers(d0.cols)), int(rng.integers(d0.nby)), int(rng.integers(d0.nbx))) for _ in range(N)]
        for flag in ((False, True) if r % 2 else (True, False)):
            tl.KEY_ROWS_RASTER_MIN = int(os.environ.get("RASTER_MIN", 1)) if flag else 10 ** 9
            d = RlfcDecoder(open_lfc(path))
            for q in req:
                t = time.perf_counter(); d.decode_block(*q); res[flag].append(time.perf_counter() - t)
    for flag in (False, True):
        a = np.array(res[flag]) * 1e6
        print(f"{g:28s} {'raster' if flag else 'blocks':6s} p50 {np.percentile(a, 50):7.1f} p90 {np.percentile(a, 90):7.1f} p99 {np.percentile(a, 99):8.1f} mean {a.mean():7.1f} µs", flush=True)
