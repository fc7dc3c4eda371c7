"""TAIL_LANES (rlfc.txparse) against 64 / 128 / 256 on the lane parses of a fresh first block, every key and
decode_all of three 40 dB files (stop 83): the same parsed integers, best of 3 ms each."""
import numpy as np, timeit
import rlfc.profiles.tx_residual as trm
import rlfc.txparse as tp
from rlfc.txparse import parse_lanes
captured = []
orig = trm.Residuals._parse_streams
def ps(self, buf, s2, e2, nt, kind, key):
    captured.append((self, buf, s2.copy(), e2.copy(), nt, np.asarray(kind).copy(), np.asarray(key).copy()))
    return orig(self, buf, s2, e2, nt, kind, key)
trm.Residuals._parse_streams = ps
from formats.lfcfile import open_lfc
from rlfc import RlfcDecoder
TLS = (32, 64, 128, 256)
for f in ["/tmp/dec/epfl_iso_chart_1.lfc", "/tmp/dec/stanford_lytro_general_11.lfc", "/tmp/dec/stanford_chess.lfc"]:
    captured.clear()
    d = RlfcDecoder(open_lfc(f)); d.decode_block(0, 0, 0, 0); getattr(d.core, "decode_keys")(); d.decode_all(threads=1)
    seen = set()
    for (self, buf, s2, e2, nt, kind, key) in captured:
        n = e2 - s2
        if n.size < 8 or (n.size, int(n.sum())) in seen: continue
        seen.add((n.size, int(n.sum())))
        if trm.ONE_BY_ONE_RATIO * max(int(n.max()), 1) > n.sum(): continue   # (parsed one by one)
        ref = parse_lanes(buf, s2, e2, self.tables, nt, self.pcs, kind, key, "")
        row = []
        for tl in TLS:
            tp.TAIL_LANES = tl
            got = parse_lanes(buf, s2, e2, self.tables, nt, self.pcs, kind, key, "")
            assert np.array_equal(got.index, ref.index) and np.array_equal(got.values, ref.values)
            row.append(min(timeit.repeat(lambda: parse_lanes(buf, s2, e2, self.tables, nt, self.pcs, kind, key, ""), number=1, repeat=3)) * 1e3)
        tp.TAIL_LANES = 32
        print(f.split('/')[-1], "streams %d bytes %d" % (n.size, n.sum()), " ".join("%d: %.1f" % (tl, t) for tl, t in zip(TLS, row)), flush=True)
        if len(seen) > 5: break
