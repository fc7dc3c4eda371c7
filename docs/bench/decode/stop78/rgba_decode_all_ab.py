# usage: python THIS.py FILE.lfc  (rlfc/_txsyntax_old.py = `git show fd561c2:rlfc/txsyntax.py`; /tmp/w/s78/pixels_old.py = `git show fd561c2:formats/pixels.py`)
import sys, time, importlib.util, numpy as np
sys.path.insert(0, ".")
import formats.pixels as fpx, rlfc.txsyntax as new, rlfc._txsyntax_old as oldsyn
import rlfc.profiles.tx as txp
spec = importlib.util.spec_from_file_location("pixels_old", "/tmp/w/s78/pixels_old.py"); oldpx = importlib.util.module_from_spec(spec); spec.loader.exec_module(oldpx)
from formats.lfcfile import open_lfc
from rlfc import RlfcDecoder
path = sys.argv[1]
impl = {"old": (oldpx._from_planes_split, oldsyn.parse_lanes), "new": (fpx._from_planes_split, new.parse_lanes)}
T = {k: [] for k in impl}; outs = {}
for r in range(8):
    for k in (("old", "new") if r % 2 == 0 else ("new", "old")):
        fpx._from_planes_split, txp.parse_lanes = impl[k]
        d = RlfcDecoder(open_lfc(path))
        t = time.perf_counter(); outs[k] = d.decode_all(threads=1); T[k].append(time.perf_counter() - t)
o, n = np.median(T["old"]), np.median(T["new"])
print(path.split("/")[-1], "open + decode_all s old %.3f new %.3f ratio %.3f same %s" % (o, n, n / o, np.array_equal(outs["old"], outs["new"])))
