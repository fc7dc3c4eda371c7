"""Estimate each view's similarity warp (rotation θ, scale s, shift t; about the view's centre)
from the views alone: dense optical flow (OpenCV DIS) between grid neighbours; the flow's
component across the pair's baseline carries no parallax, so it is the difference of the two
views' warps there (horizontal pairs give θ, s, ty of the difference; vertical pairs θ, s, tx);
per-view parameters by least squares over all pairs (the mean view fixed at identity)."""
import numpy as np, cv2


def estimate(views):
    r, c, h, w, _ = views.shape
    cy, cx = h / 2 - 0.5, w / 2 - 0.5
    grey = [cv2.cvtColor(np.ascontiguousarray(views[i, j]), cv2.COLOR_RGB2GRAY) for i in range(r) for j in range(c)]
    dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    m = 16                                          # border left out
    Y, X = yy[m:-m, m:-m].ravel() - cy, xx[m:-m, m:-m].ravel() - cx
    rows, rhs = [], []
    n = r * c
    # unknowns per view: theta, s, tx, ty (4n)
    def add(i, j, coef, val):
        row = np.zeros(4 * n)
        for k, a in coef.items():
            row[4 * j + k] += a          # view j (the target: flow from i to j)
            row[4 * i + k] -= a
        rows.append(row); rhs.append(val)
    for i in range(r):
        for j in range(c):
            u = i * c + j
            for (di, dj) in ((0, 1), (1, 0)):
                if i + di >= r or j + dj >= c:
                    continue
                v = (i + di) * c + (j + dj)
                f = dis.calc(grey[u], grey[v], None).astype(np.float64)   # grey[u](x) ≈ grey[v](x + f)
                fy, fx = f[m:-m, m:-m, 1].ravel(), f[m:-m, m:-m, 0].ravel()
                # view k's pixel x (centred) comes from the rectified point q: x = (1+s_k) R(θ_k) q + t_k;
                # small: x ≈ q + s_k q + θ_k J q + t_k, J q = (−q_y, q_x) in (x, y). Flow u→v at x:
                # parallax + (s_v − s_u) q + (θ_v − θ_u) J q + (t_v − t_u)
                if di == 0:      # horizontal pair: the y component is free of parallax
                    A = np.stack([X, Y, np.ones_like(X)], 1)          # θ·X + s·Y + ty
                    sol = np.linalg.lstsq(A, fy, rcond=None)[0]
                    # robust: refit on the inliers
                    res = fy - A @ sol
                    keep = np.abs(res) < 3 * np.median(np.abs(res)) + 1e-6
                    sol = np.linalg.lstsq(A[keep], fy[keep], rcond=None)[0]
                    add(u, v, {0: 1.0}, sol[0]); add(u, v, {1: 1.0}, sol[1]); add(u, v, {3: 1.0}, sol[2])
                else:            # vertical pair: the x component is free of parallax: s·X − θ·Y + tx
                    A = np.stack([X, -Y, np.ones_like(X)], 1)
                    sol = np.linalg.lstsq(A, fx, rcond=None)[0]
                    res = fx - A @ sol
                    keep = np.abs(res) < 3 * np.median(np.abs(res)) + 1e-6
                    sol = np.linalg.lstsq(A[keep], fx[keep], rcond=None)[0]
                    add(u, v, {1: 1.0}, sol[0]); add(u, v, {0: 1.0}, sol[1]); add(u, v, {2: 1.0}, sol[2])
    # gauge: the mean of each parameter over the views is 0
    for k in range(4):
        row = np.zeros(4 * n); row[k::4] = 1.0
        rows.append(row * 10); rhs.append(0.0)
    p = np.linalg.lstsq(np.array(rows), np.array(rhs), rcond=None)[0].reshape(n, 4)
    mats = []
    for th, s, tx, ty in p:
        # x = (1+s) R(θ) q + t + (I − (1+s)R(θ)) c  (about the centre), as a 2×3 matrix taking q to x
        a, b = (1 + s) * np.cos(th), (1 + s) * np.sin(th)
        M = np.array([[a, -b, tx], [b, a, ty]])
        M[:, 2] += np.array([cx, cy]) - M[:, :2] @ np.array([cx, cy])
        mats.append(M)
    return mats, p
