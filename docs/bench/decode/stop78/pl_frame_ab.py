# usage: python THIS.py FILE.lfc ...   with rlfc/_txsyntax_old.py = `git show BASE:rlfc/txsyntax.py`
import sys, time, numpy as np
sys.path.insert(0, ".")
import rlfc.txsyntax as new, rlfc._txsyntax_old as old
import rlfc.profiles.tx as txp
import rlfc.render  # noqa: F401
from formats.lfcfile import open_lfc
from rlfc import RlfcDecoder
impl = {"old": old.parse_lanes, "new": new.parse_lanes}
for path in sys.argv[1:]:
    RlfcDecoder(open_lfc(path)).decode_block(0, 0, 0, 0)
    T = {k: [] for k in impl}; res = {}
    for r in range(int(__import__("os").environ.get("ROUNDS", "10"))):
        for k in (("old", "new") if r % 2 == 0 else ("new", "old")):
            txp.parse_lanes = impl[k]
            t = time.perf_counter()
            d = RlfcDecoder(open_lfc(path))
            rad = min(d.rows, d.cols) / 3
            res[k] = d.renderer(cache_mib=1024).render((d.rows - 1) / 2, (d.cols - 1) / 2 + rad)
            T[k].append(time.perf_counter() - t)
    same = np.array_equal(np.asarray(res["old"]), np.asarray(res["new"]))
    mo, mn = np.median(T["old"]), np.median(T["new"])
    print(path.split("/")[-1], "open + first frame ms old %.1f new %.1f ratio %.3f (best %.3f) same %s" % (mo * 1e3, mn * 1e3, mn / mo, min(T["new"]) / min(T["old"]), same))
