"""batched decode_blocks: the profile's pixels path (new) against from_planes after the blocks (old), toggled in one process."""
import sys, os, time, hashlib
os.environ["OMP_NUM_THREADS"] = "1"
sys.path.insert(0, "/work/main")
import numpy as np
from formats.lfcfile import open_lfc
from rlfc import RlfcDecoder
import rlfc.profiles.tx as txp
th = int(os.environ.get("TH", 1))
for path in sys.argv[1:]:
    d = RlfcDecoder(open_lfc(path)); c = d.core; c.decode_keys(); c.decode_maps()
    rng = np.random.default_rng(0); n = d.rows * d.cols; N = 20000
    v, by, bx = rng.integers(0, n, N), rng.integers(0, d.nby, N), rng.integers(0, d.nbx, N)
    h = {}
    for k in (False, True):
        txp.TxDecoder.blocks_to_pixels = k
        h[k] = hashlib.sha1(d.decode_blocks(v, by, bx, threads=th).tobytes()).hexdigest()[:12]
    assert h[False] == h[True], h
    T = {False: [], True: []}
    for rnd in range(10):
        for k in ((False, True) if rnd % 2 == 0 else (True, False)):
            txp.TxDecoder.blocks_to_pixels = k
            t = time.perf_counter(); d.decode_blocks(v, by, bx, threads=th); T[k].append(time.perf_counter() - t)
    o, w = np.median(T[False]), np.median(T[True])
    print(os.path.basename(path), "thr", th, "same", h[True], "old %.1f new %.1f Mpix/s (median), best %.1f / %.1f; new/old time %.3f" % (N*256/o/1e6, N*256/w/1e6, N*256/min(T[False])/1e6, N*256/min(T[True])/1e6, w/o), flush=True)
