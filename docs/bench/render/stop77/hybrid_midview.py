import sys, numpy as np, cv2
from formats.scenes import read_scene
name = sys.argv[1]; STEP = int(sys.argv[2])
lf = read_scene(f"/work/shared/data/{name}")
V = lf.views.astype(np.float32)
R, C = lf.rows, lf.cols
print(name, V.shape, R, C)
def psnr(a, b, m=20):
    e = (a[m:-m, m:-m] - b[m:-m, m:-m]) ** 2
    return 10 * np.log10(255 ** 2 / e.mean())
def shift(img, dx, dy=0.0, interp=cv2.INTER_CUBIC):
    M = np.float32([[1, 0, dx], [0, 1, dy]])
    return cv2.warpAffine(img, M, (img.shape[1], img.shape[0]), flags=interp, borderMode=cv2.BORDER_REFLECT)
def grey(a): return cv2.cvtColor(a, cv2.COLOR_RGB2GRAY)
res = []
for r in range(R):
    for c in range(STEP, C - STEP):
        a, m, b = V[r, c - STEP], V[r, c], V[r, c + STEP]
        (sx, sy), _ = cv2.phaseCorrelate(grey(a), grey(b))
        d = sx / 2            # per step: b = a shifted by 2d
        # a(x) ~ m(x + ...) : move a by +d toward m, b by -d
        mean0 = (a + b) / 2
        sh = (shift(a, d, sy / 2) + shift(b, -d, -sy / 2)) / 2
        out = [psnr(mean0, m), psnr(sh, m)]
        for sig in (0.7, 1.0, 1.5, 2.5):
            la, lb = cv2.GaussianBlur(a, (0, 0), sig), cv2.GaussianBlur(b, (0, 0), sig)
            hyb = (shift(la, d, sy / 2) + shift(lb, -d, -sy / 2)) / 2 + ((a - la) + (b - lb)) / 2
            out.append(psnr(hyb, m))
        res.append([d] + out)
res = np.array(res)
print("d per step median %.3f" % np.median(res[:, 0]))
print("mean0 %.2f shifted %.2f hybrid sig0.7 %.2f sig1 %.2f sig1.5 %.2f sig2.5 %.2f" % tuple(np.mean(res[:, 1:], 0)))
