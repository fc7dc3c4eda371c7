"""Where one-by-one parsing and lanes cross after the uint32 magnitude steps (stop 87): every
`_parse_streams` call of a fresh first block, every key, decode_all and a first frame of four 40 dB
files, parsed both ways (the same integers), best of 3 ms each, against bytes / longest stream."""
import sys, timeit
import numpy as np
from rlfc.txparse import parse_lanes, concat_parsed
from rlfc.txparse_one import parse_one
sys.path.insert(0, __file__.rsplit('/', 1)[0])
import captures
captured = captures.parse_streams()
from formats.lfcfile import open_lfc
from rlfc import RlfcDecoder
for f in sys.argv[1:]:
    captured.clear()
    d = RlfcDecoder(open_lfc(f)); d.decode_block(0, 0, 0, 0); d.core.decode_keys(); d.decode_all(threads=1)
    d3 = RlfcDecoder(open_lfc(f)); rad = min(d3.rows, d3.cols) / 3
    d3.renderer(cache_mib=1024).render((d3.rows - 1) / 2, (d3.cols - 1) / 2 + rad)
    seen = set()
    for (self, buf, s2, e2, nt, kind, key) in captured:
        n = e2 - s2
        if n.size < 2 or (n.size, int(n.sum()), nt) in seen:
            continue
        seen.add((n.size, int(n.sum()), nt))
        ratio = n.sum() / max(int(n.max()), 1)
        if ratio > 200:
            continue
        def one():
            return concat_parsed([parse_one(bytes(buf[a:b]), self.tables, nt, self._pcl, int(k), int(y))
                                  for a, b, k, y in zip(s2.tolist(), e2.tolist(), kind.tolist(), key.tolist())])
        def lanes():
            return parse_lanes(buf, s2, e2, self.tables, nt, self.pcs, kind, key, "")
        a, b = one(), lanes()
        assert np.array_equal(a.index, b.index) and np.array_equal(a.values, b.values)
        t1 = min(timeit.repeat(one, number=1, repeat=3)) * 1e3
        t2 = min(timeit.repeat(lanes, number=1, repeat=3)) * 1e3
        print(f"{f.split('/')[-1]:30s} nt {nt:4d} streams {n.size:5d} bytes {int(n.sum()):8d} ratio {ratio:6.1f} one {t1:7.1f} ms lanes {t2:7.1f} ms lanes/one {t2/t1:.2f}", flush=True)
