# usage: python THIS.py FILE.lfc ...   with rlfc/_txsyntax_old.py = `git show BASE:rlfc/txsyntax.py`
import sys, time, numpy as np
sys.path.insert(0, ".")
import rlfc.txsyntax as new, rlfc._txsyntax_old as old
import rlfc.profiles.tx as txp
from formats.lfcfile import open_lfc
from rlfc import RlfcDecoder
impl = {"old": old.parse_lanes, "new": new.parse_lanes}
for path in sys.argv[1:]:
    d = RlfcDecoder(open_lfc(path)); c = d.core; c.decode_keys(); c.decode_maps()
    n = d.rows * d.cols
    for v in range(n): d.decode_view(*divmod(v, d.cols))
    rng = np.random.default_rng(0)
    T = {k: [] for k in impl}; res = {}
    for r in range(8):
        seq = rng.permutation(n)[:12].tolist()
        for k in (("old", "new") if r % 2 == 0 else ("new", "old")):
            txp.parse_lanes = impl[k]
            outs = []
            t = time.perf_counter()
            for v in seq: outs.append(d.decode_view(*divmod(v, d.cols)))
            T[k].append((time.perf_counter() - t) / len(seq))
            res[k] = outs
    same = all(np.array_equal(a, b) for a, b in zip(res["old"], res["new"]))
    mo, mn = np.median(T["old"]), np.median(T["new"])
    print(path.split("/")[-1], "view ms old %.2f new %.2f ratio %.3f (best %.3f) same %s" % (mo * 1e3, mn * 1e3, mn / mo, min(T["new"]) / min(T["old"]), same))
