"""Capture the parse_one calls of a first frame (args pickled) for timing variants."""
import sys, pickle
from formats.lfcfile import open_lfc
from rlfc import RlfcDecoder
import rlfc.render  # noqa
import rlfc.profiles.tx_residual as tr
calls = []
orig = tr.parse_one
def cap(data, tables, nt, pcs, kind, key):
    calls.append((data, nt, list(pcs) if not isinstance(pcs, list) else pcs, kind, key))
    return orig(data, tables, nt, pcs, kind, key)
tr.parse_one = cap
d = RlfcDecoder(open_lfc(sys.argv[1]))
rad = min(d.rows, d.cols) / 3
d.renderer(cache_mib=256).render((d.rows - 1) / 2, (d.cols - 1) / 2 + rad)
print(len(calls), sum(len(c[0]) for c in calls), "bytes")
pickle.dump((sys.argv[1], calls), open(sys.argv[2], "wb"))
