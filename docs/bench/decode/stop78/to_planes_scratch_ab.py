import sys, time, numpy as np, cv2
sys.path.insert(0, ".")
import formats.pixels as fpx
def new_to(x):
    C = x.shape[-1]
    img = x.reshape(-1, x.shape[-2], C)
    k = img.shape[0] * img.shape[1]
    sc = fpx._scratch_planes(C, k)
    planes = [q[:k].reshape(img.shape[:2]) for q in sc[:C]]
    for q, u in zip(planes, cv2.split(img)):
        np.copyto(q, u)
    r, g, b = planes[:3]
    co = np.subtract(r, b, out=r)
    b += co >> 1
    cg = np.subtract(g, b, out=g)
    b += cg >> 1
    return cv2.merge([b, co, cg] + planes[3:]).reshape(x.shape)
rng = np.random.default_rng(0)
for (H, W) in [(512, 512), (448, 448), (376, 512)]:
    px = rng.integers(0, 256, (H, W, 3), dtype=np.uint8)
    T = {"old": [], "new": []}
    for r in range(100):
        for k, f in (("old", fpx._to_planes_split), ("new", new_to)) if r % 2 else (("new", new_to), ("old", fpx._to_planes_split)):
            t = time.perf_counter(); o = f(px); T[k].append(time.perf_counter() - t)
            assert np.array_equal(o, fpx.forward_int(px.astype(np.int32)))
    print((H, W), "old %.3f new %.3f ms ratio %.3f" % (np.median(T["old"]) * 1e3, np.median(T["new"]) * 1e3, np.median(T["new"]) / np.median(T["old"])))
