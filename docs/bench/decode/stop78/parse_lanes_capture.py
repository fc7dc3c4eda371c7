# usage: python THIS.py FILE.lfc OUT.pkl [views]: the parse_lanes calls of an open + first frame (+ two whole views), pickled
import sys, pickle
sys.path.insert(0, ".")
from formats.lfcfile import open_lfc
from rlfc import RlfcDecoder
import rlfc.render  # noqa: F401
import rlfc.txsyntax as ts, rlfc.profiles.tx as txp
path, out = sys.argv[1], sys.argv[2]
calls = []
orig = ts.parse_lanes
def rec(*a, **k):
    calls.append((a, k)); return orig(*a, **k)
txp.parse_lanes = rec
d3 = RlfcDecoder(open_lfc(path))
rad = min(d3.rows, d3.cols) / 3
d3.renderer(cache_mib=1024).render((d3.rows - 1) / 2, (d3.cols - 1) / 2 + rad)
if len(sys.argv) > 3:           # also whole views
    d3.decode_view(0, 1); d3.decode_view(1, 1)
print(len(calls), [a[1].size for a, k in calls])
pickle.dump(calls, open(out, "wb"))
