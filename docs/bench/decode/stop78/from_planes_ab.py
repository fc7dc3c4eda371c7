import sys, time, importlib.util, numpy as np
# usage: python THIS.py OLD_PIXELS.py [args]  (OLD_PIXELS.py: `git show fd561c2:formats/pixels.py` or any older formats/pixels.py)
sys.path.insert(0, ".")
import formats.pixels as fpx
spec = importlib.util.spec_from_file_location("pixels_old", sys.argv.pop(1)); old = importlib.util.module_from_spec(spec); spec.loader.exec_module(old)
rng = np.random.default_rng(0)
for (H, W) in [(512, 512), (448, 448), (432, 512), (376, 512), (304, 432)]:
    px = rng.integers(0, 256, (H, W, 3), dtype=np.uint8)
    p = fpx.to_planes(px)
    T = {"old": [], "new": []}
    for r in range(200):
        for k, f in (("old", old._from_planes_split), ("new", fpx._from_planes_split)) if r % 2 else (("new", fpx._from_planes_split), ("old", old._from_planes_split)):
            t = time.perf_counter(); o = f(p, 255, np.uint8); T[k].append(time.perf_counter() - t)
    assert np.array_equal(o, px)
    print((H, W), "old %.3f new %.3f ms ratio %.3f" % (np.median(T["old"]) * 1e3, np.median(T["new"]) * 1e3, np.median(T["new"]) / np.median(T["old"])))
