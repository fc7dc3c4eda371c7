"""The key rows' rANS lanes of a 40 dB file parsed in one parse_lanes call against two calls on
halves on two threads (the same syntax, checked). Stop 82; not adopted.

    OMP_NUM_THREADS=1 python lanes_two_threads.py FILE.lfc FRACTION_OF_KEY_STREAMS
"""
import sys, time
import numpy as np
from concurrent.futures import ThreadPoolExecutor
from formats import open_lfc
from rlfc import RlfcDecoder
from rlfc.txparse import parse_lanes, concat_parsed
path = sys.argv[1]; frac = float(sys.argv[2])
d = RlfcDecoder(open_lfc(path)); c = d.core
s, e = c.key_start.reshape(-1), c.key_end.reshape(-1)
keep = np.flatnonzero(e > s)
keep = keep[: int(keep.size * frac)]
buf, s2, e2 = c._streams(s[keep], e[keep])
nt = c.nt * c.nbx // c.key_split
kind = np.zeros(s2.size, np.int64); key = np.ones(s2.size, np.int64)
def one(a, b): return parse_lanes(buf, s2[a:b], e2[a:b], c.tables, nt, c.pcs, kind[a:b], key[a:b], "x")
ex = ThreadPoolExecutor(2)
for r in range(3):
    t = time.perf_counter(); p1 = one(0, s2.size); t1 = time.perf_counter() - t
    h = s2.size // 2
    t = time.perf_counter(); f = [ex.submit(one, 0, h), ex.submit(one, h, s2.size)]; p2 = concat_parsed([x.result() for x in f]); t2 = time.perf_counter() - t
    print("lanes", s2.size, "1 thread %.1f ms, 2 threads %.1f ms" % (t1 * 1e3, t2 * 1e3), np.array_equal(p1.index, p2.index) and np.array_equal(p1.values, p2.values) and np.array_equal(p1.modes, p2.modes))
