"""One fresh process: first frame, a fresh view and a second view of FILE (ms, JSON); ff_ab.py runs it on two checkouts alternated."""
import sys, time, json
from formats.lfcfile import open_lfc
from rlfc import RlfcDecoder
import rlfc.render  # noqa: F401  (its modules warm)
path = sys.argv[1]
RlfcDecoder(open_lfc(path)).decode_block(0, 0, 0, 0)
out = {}
t = time.perf_counter(); d3 = RlfcDecoder(open_lfc(path)); t1 = time.perf_counter()
rad = min(d3.rows, d3.cols) / 3
d3.renderer(cache_mib=1024).render((d3.rows - 1) / 2, (d3.cols - 1) / 2 + rad)
out["first_frame_ms"] = (time.perf_counter() - t1) * 1e3
t = time.perf_counter(); d = RlfcDecoder(open_lfc(path)); d.decode_view(d.rows // 2, d.cols // 2 + 1); out["fresh_view_ms"] = (time.perf_counter() - t) * 1e3
t = time.perf_counter(); d.decode_view(d.rows // 2 + 1, d.cols // 2); out["second_view_ms"] = (time.perf_counter() - t) * 1e3
print(json.dumps(out))
