import sys, time, numpy as np, cv2
from formats.pixels import to_planes, from_planes
if sys.argv[1] == "keep":
    from formats.heap import keep_freed; keep_freed()
rng = np.random.default_rng(0)
px = rng.integers(0, 256, (512, 512, 3), dtype=np.uint8)
p = to_planes(px)
def tm(f, n=40):
    ts=[]
    for i in range(n):
        t=time.perf_counter(); f(); ts.append(time.perf_counter()-t)
    return round(np.median(ts)*1e3,3)
mv = [np.empty((512,512), np.int32) for _ in range(3)]
print(sys.argv[1], "split", tm(lambda: cv2.split(p)), "split mv", tm(lambda: cv2.split(p, mv)),
      "chunk split", tm(lambda: cv2.split(p[:170])), "from_planes", tm(lambda: from_planes(p)))
o = cv2.split(p, mv); print(o[0] is mv[0] if isinstance(o, (list, tuple)) else type(o))
