"""Rectifying a grid of views whose cameras are slightly rotated, scaled or shifted (a rig that
is not rectified): each view's similarity warp is estimated from the views alone and undone, so
that the grid's parallax is again a shift along the grid's axes (what the codecs' prediction
and the renderers assume).

Estimation (``estimate_warps``): dense optical flow (OpenCV's DIS) between each pair of grid
neighbours. The component of the flow across the pair's baseline carries no parallax (a
horizontal neighbour sees the scene shifted horizontally only), so it is the difference of
the two views' warps there: a horizontal pair gives the difference's rotation, scale and
vertical shift, a vertical pair its rotation, scale and horizontal shift (a robust linear fit
over the pair's pixels). Each view's four numbers then come from least squares over all pairs,
their mean over the views fixed at zero (the rectified grid is the views' average geometry).
On hci_antinous with rotations of ±0.5° the angles come back within 0.011° rms (BENCHMARKS.md).

Warps are small-angle similarities about the view's centre, as (θ radians, s, tx, ty): a point
q of the rectified view lies at x = (1 + s)·R(θ)·(q − c) + c + t in the captured view, in pixel
coordinates (x right, y down), c the view's centre.
"""
from __future__ import annotations

import numpy as np

from .errors import ParameterError
from .parallel import Runner

#: views whose estimated warps move no pixel by more than this (px) are left as they are
MIN_CORRECTION_PX = 0.5
#: the flow is computed on views downscaled to at most this many pixels on their long side
FLOW_SIDE = 640
#: border (px, at flow scale) left out of each pair's fit
FLOW_BORDER = 12
#: each pair's fit reads the flow at every FIT_STRIDE-th pixel of each row and column
FIT_STRIDE = 2


def _grey8(view: np.ndarray) -> np.ndarray:
    """(H, W) uint8 luma of one view (grey, grey + alpha, RGB or RGBA; 8 or 16 bit)."""
    import cv2

    v = np.asarray(view)
    x = v[..., 0] if v.shape[-1] < 3 else v[..., :3].astype(np.float32) @ np.float32([0.299, 0.587, 0.114])
    scale = 255.0 / float(np.iinfo(v.dtype).max)
    return cv2.convertScaleAbs(np.ascontiguousarray(x, np.float32), alpha=scale)


def _pair_fit(a: np.ndarray, b: np.ndarray, horizontal: bool, X: np.ndarray, Y: np.ndarray, dis) -> np.ndarray:
    """(θ, s, shift) of the warp difference b − a across the pair's baseline: the flow from a to b
    across it (vertical component for a horizontal pair, horizontal for a vertical one) fitted
    as θ·X + s·Y + ty, or s·X − θ·Y + tx, then refitted on the pixels within 3 median
    deviations of the first fit."""
    m = FLOW_BORDER
    f = dis.calc(a, b, None)[m:-m:FIT_STRIDE, m:-m:FIT_STRIDE]
    y = (f[..., 1] if horizontal else f[..., 0]).reshape(-1).astype(np.float64)
    ones = np.ones_like(X)
    A = np.stack([X, Y, ones], 1) if horizontal else np.stack([-Y, X, ones], 1)     # columns: θ, s, shift
    sol = np.linalg.lstsq(A, y, rcond=None)[0]
    res = np.abs(y - A @ sol)
    keep = res <= 3 * np.median(res) + 1e-9
    return np.linalg.lstsq(A[keep], y[keep], rcond=None)[0]


def estimate_warps(views: np.ndarray) -> np.ndarray:
    """Each view's similarity warp, estimated from the views.

    Args:
        views: (rows, cols, H, W, C) uint8 or uint16 views of a grid (rows·cols ≥ 2).

    Returns:
        (rows·cols, 4) float64: θ (radians), s, tx, ty (px) per view, row-major, their means 0.
        A vertical shift shared by a whole row of views, or a horizontal one shared by a
        column, cannot be told from where those cameras stand (parallax): those parts are 0
        (a 1-row grid's horizontal shifts are 0, a 1-column grid's vertical ones).
    """
    import cv2

    r, c, h, w = views.shape[:4]
    if r * c < 2:
        raise ParameterError("rectifying needs a grid of at least two views")
    k = min(1.0, FLOW_SIDE / max(h, w))
    hs, ws = max(2 * FLOW_BORDER + 8, int(round(h * k))), max(2 * FLOW_BORDER + 8, int(round(w * k)))
    ky, kx = hs / h, ws / w
    grey = [cv2.resize(_grey8(views[i, j]), (ws, hs), interpolation=cv2.INTER_AREA) if k < 1 else _grey8(views[i, j])
            for i in range(r) for j in range(c)]
    yy, xx = np.mgrid[FLOW_BORDER:hs - FLOW_BORDER:FIT_STRIDE, FLOW_BORDER:ws - FLOW_BORDER:FIT_STRIDE].astype(np.float64)
    Y, X = (yy.reshape(-1) + 0.5) / ky - h / 2, (xx.reshape(-1) + 0.5) / kx - w / 2    # full-size, centred
    n = r * c
    pairs = [(i * c + j, (i + di) * c + j + dj, di == 0) for i in range(r) for j in range(c)
             for di, dj in ((0, 1), (1, 0)) if i + di < r and j + dj < c]

    def fit(u: int, v: int, horizontal: bool) -> np.ndarray:
        dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)     # (one per task: not shared)
        # (the flow is in downscaled pixels, the fit's coordinates full-size ones)
        return _pair_fit(grey[u], grey[v], horizontal, X, Y, dis) / (ky if horizontal else kx)

    fits = Runner().map_threaded(fit, pairs)              # (OpenCV's flow releases the GIL)
    rows, rhs = [], []
    for (u, v, horizontal), (th, s, sh) in zip(pairs, fits):
        for col, val in ((0, th), (1, s), (3 if horizontal else 2, sh)):
            row = np.zeros(4 * n)
            row[4 * v + col], row[4 * u + col] = 1.0, -1.0
            rows.append(row)
            rhs.append(val)
    for col in range(4):                                   # the gauge: each parameter's mean is 0
        row = np.zeros(4 * n)
        row[col::4] = 1.0
        rows.append(row)
        rhs.append(0.0)
    # (a scene point at x in view u lies at x + flow in view v: for small warps the flow
    # across the baseline is warp v less warp u there, each fitted row one such difference)
    return np.linalg.lstsq(np.array(rows), np.array(rhs), rcond=None)[0].reshape(n, 4)


def warp_matrix(warp, h: int, w: int) -> np.ndarray:
    """(2, 3) matrix taking a rectified view's pixel (x, y) to the captured view's, for one
    warp (θ, s, tx, ty) of :func:`estimate_warps` (about the view's centre)."""
    th, s, tx, ty = (float(x) for x in warp)
    a, b = (1 + s) * np.cos(th), (1 + s) * np.sin(th)
    M = np.array([[a, -b, tx], [b, a, ty]])
    cen = np.array([w / 2 - 0.5, h / 2 - 0.5])
    M[:, 2] += cen - M[:, :2] @ cen
    return M


def largest_correction(warps: np.ndarray, h: int, w: int) -> float:
    """The largest distance (px) any corner of any view moves under its warp."""
    corners = np.array([[0, 0, 1], [w - 1, 0, 1], [0, h - 1, 1], [w - 1, h - 1, 1]], np.float64)
    out = 0.0
    for wp in warps:
        M = warp_matrix(wp, h, w)
        out = max(out, float(np.hypot(*(corners @ M.T - corners[:, :2]).T).max()))
    return out


def estimate_correction(views: np.ndarray) -> tuple[np.ndarray, float, bool]:
    """(warps of :func:`estimate_warps`, their :func:`largest_correction` in px, whether that
    reaches :data:`MIN_CORRECTION_PX`) of grid views (rows, cols, H, W, C): what ``--rectify``
    and ``--warps`` decide on."""
    warps = estimate_warps(views)
    big = largest_correction(warps, *views.shape[2:4])
    return warps, big, bool(big >= MIN_CORRECTION_PX)


def rectify_views(views: np.ndarray, warps: np.ndarray) -> np.ndarray:
    """The views resampled onto the rectified grid (bicubic, edges replicated, rounded and
    clipped to the dtype): rectified view v at q = captured view v at its warp's x(q).

    Args:
        views: (rows, cols, H, W, C) uint8/uint16; warps: (rows·cols, 4) of :func:`estimate_warps`.

    Returns:
        a new array of the views' shape and dtype.
    """
    import cv2

    r, c, h, w, ch = views.shape
    out = np.empty_like(views)
    for idx, (i, j) in enumerate(np.ndindex(r, c)):
        M = warp_matrix(warps[idx], h, w)
        got = cv2.warpAffine(np.ascontiguousarray(views[i, j]), M, (w, h),
                             flags=cv2.INTER_CUBIC | cv2.WARP_INVERSE_MAP, borderMode=cv2.BORDER_REPLICATE)
        out[i, j] = got.reshape(h, w, ch)
    return out


def rectify_grid(lf):
    """(light field, report) for a grid light field ``lf``: its views rectified where the
    estimated warps move some pixel by at least :data:`MIN_CORRECTION_PX`, else ``lf`` as it
    is. ``report``: {"applied", "largest_correction_px", "warps"} (warps as lists of θ, s, tx,
    ty, rounded).

    Raises:
        ParameterError: ``lf`` is not a grid of two or more views.
    """
    from .lightfield import LightField

    if lf.layout != "grid" or lf.rows * lf.cols < 2:
        raise ParameterError("--rectify works on a grid of two or more views (a posed capture's cameras are its "
                             "own poses)")
    views = np.asarray(lf.views)
    warps, big, applied = estimate_correction(views)
    report = {"applied": applied, "largest_correction_px": round(big, 3), "warps": np.round(warps, 7).tolist()}
    if not report["applied"]:
        return lf, report
    meta = {**lf.meta, "rectified": {"largest_correction_px": round(big, 3),
                                      "method": "a similarity per view from optical flow across each "
                                                "neighbour pair's baseline (lfcodec --rectify)"}}
    return LightField(views=rectify_views(views, warps), positions=lf.positions, focal=lf.focal,
                      principal=lf.principal, layout=lf.layout, meta=meta), report
