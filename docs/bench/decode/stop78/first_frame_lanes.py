# usage: python THIS.py FILE.lfc ...  (lanes, steps and symbols of each lane parse of an open and its first frame)
import sys
sys.path.insert(0, ".")
import rlfc.txsyntax as ts
from formats.lfcfile import open_lfc
from rlfc import RlfcDecoder
import rlfc.render  # noqa: F401
orig = ts._magnitudes; stats = []
def wrap(dec, tables, S, per_lane, *a):
    stats.append((S, int(per_lane.max()), int(per_lane.sum()))); return orig(dec, tables, S, per_lane, *a)
ts._magnitudes = wrap
for f in sys.argv[1:]:
    stats.clear()
    d = RlfcDecoder(open_lfc(f)); rad = min(d.rows, d.cols) / 3
    d.renderer(cache_mib=1024).render((d.rows - 1) / 2, (d.cols - 1) / 2 + rad)
    print(f.split("/")[-1], "first frame parse calls (lanes, K, symbols):", stats)
