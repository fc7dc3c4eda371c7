"""Captures the _magnitudes calls of a first frame and a view (run on the code before: PYTHONPATH=OLD) with their outputs into caps.pkl for ab.py."""
import sys, pickle
sys.path.insert(0, __file__.rsplit('/', 1)[0])
import captures
caps = []
captures.magnitudes(caps)
from formats.lfcfile import open_lfc
from rlfc import RlfcDecoder
import rlfc.render  # noqa: F401  (its modules warm)
for name in sys.argv[1:]:
    d3 = RlfcDecoder(open_lfc(f"/tmp/dec/{name}.lfc"))
    rad = min(d3.rows, d3.cols) / 3
    d3.renderer(cache_mib=1024).render((d3.rows - 1) / 2, (d3.cols - 1) / 2 + rad)
    d3.decode_view(d3.rows//2, d3.cols//2 + 1)
for c in caps:
    c["tables"] = (c["tables"].freq, c["tables"].cum)
pickle.dump(caps, open("/tmp/w87/caps.pkl", "wb"))
print(len(caps), [c["S"] for c in caps], [c["ctx1"].size for c in caps])
