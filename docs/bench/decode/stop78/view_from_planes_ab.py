import sys, time, importlib.util, numpy as np
# usage: python THIS.py OLD_PIXELS.py [args]  (OLD_PIXELS.py: `git show fd561c2:formats/pixels.py` or any older formats/pixels.py)
sys.path.insert(0, ".")
import formats.pixels as fpx
spec = importlib.util.spec_from_file_location("pixels_old", sys.argv.pop(1)); old = importlib.util.module_from_spec(spec); spec.loader.exec_module(old)
from formats.lfcfile import open_lfc
from rlfc import RlfcDecoder
impl = {"old": old._from_planes_split, "new": fpx._from_planes_split}
res = {}
for path in sys.argv[1:]:
    d = RlfcDecoder(open_lfc(path)); c = d.core; c.decode_keys(); c.decode_maps()
    n = d.rows * d.cols
    for v in range(n): d.decode_view(*divmod(v, d.cols))
    rng = np.random.default_rng(0)
    T = {k: [] for k in impl}
    for r in range(6):
        seq = rng.permutation(n)[:16].tolist()
        for k in (("old", "new") if r % 2 == 0 else ("new", "old")):
            fpx._from_planes_split = impl[k]
            outs = []
            t = time.perf_counter()
            for v in seq: outs.append(d.decode_view(*divmod(v, d.cols)))
            T[k].append((time.perf_counter() - t) / len(seq))
            res[k] = outs
    same = all(np.array_equal(a, b) for a, b in zip(res["old"], res["new"]))
    mo, mn = np.median(T["old"]), np.median(T["new"])
    print(path.split("/")[-1], "view ms old %.2f new %.2f ratio %.3f same %s" % (mo * 1e3, mn * 1e3, mn / mo, same))
