"""Key rows of predicted keys in raster bands (KEY_ROWS_RASTER) against block by block, alternated
in one process: a fresh decoder's first frame (the robust renderer, as ffw.py) and decode_keys().
python ab.py ROUNDS GRID..."""
import os, sys, time, statistics
from formats.lfcfile import open_lfc
from rlfc import RlfcDecoder
import rlfc.render  # noqa: F401
import rlfc.profiles.tx_lazy as tl
rounds = int(sys.argv[1])
for g in sys.argv[2:]:
    path = f"/tmp/dec/{g}.lfc"
    RlfcDecoder(open_lfc(path)).decode_block(0, 0, 0, 0)
    res = {(w, f): [] for w in ("frame", "keys") for f in (False, True)}
    for r in range(rounds):
        for flag in ((False, True) if r % 2 else (True, False)):
            tl.KEY_ROWS_RASTER_MIN = int(os.environ.get("RASTER_MIN", 1)) if flag else 10 ** 9
            d = RlfcDecoder(open_lfc(path))
            rad = min(d.rows, d.cols) / 3
            t = time.perf_counter()
            d.renderer(cache_mib=1024).render((d.rows - 1) / 2, (d.cols - 1) / 2 + rad)
            res[("frame", flag)].append(time.perf_counter() - t)
            d = RlfcDecoder(open_lfc(path))
            t = time.perf_counter()
            d.decode_keys()
            res[("keys", flag)].append(time.perf_counter() - t)
    for w in ("frame", "keys"):
        a, b = statistics.median(res[(w, False)]), statistics.median(res[(w, True)])
        print(f"{g:28s} {w:6s} blocks {a*1e3:7.1f} ms raster {b*1e3:7.1f} ms x{b/a:.3f}", flush=True)
