import sys, os, time, resource, json, numpy as np
import rlfc
from rlfc import RlfcDecoder
from formats import open_lfc
path = sys.argv[1]
d = RlfcDecoder(open_lfc(path)); d.decode_keys(); d.decode_maps()
n = d.rows * d.cols
rng = np.random.default_rng(0)
M = 20000
v, by, bx = rng.integers(0, n, M), rng.integers(0, d.nby, M), rng.integers(0, d.nbx, M)
d.decode_blocks(v, by, bx)
def flt(): return resource.getrusage(resource.RUSAGE_SELF).ru_minflt
out = {}
for th in (1, 2):
    f0 = flt(); ts = []
    for _ in range(3):
        t = time.perf_counter(); d.decode_blocks(v, by, bx, threads=th); ts.append(time.perf_counter() - t)
    out[f'mpix_t{th}'] = round(M * d.block_size ** 2 / min(ts) / 1e6, 1); out[f'flt_t{th}'] = (flt() - f0) // 3
print(json.dumps({'src': os.path.dirname(rlfc.__file__), 'file': path.split('/')[-1], **out}), flush=True)
