"""Disparity-compensated prediction for the ``dcp`` profile.

Views on a grid are clustered 3×3; each cluster's key view is its most central member, coded
as a top-level image. A view at grid offset (oy, ox) from its key view is predicted, block by
block, from the decoded key view shifted by d·(oy, ox) pixels, d an integer disparity stored per
(cluster, block location). The prediction reads only the key view (held decoded in memory), so
one block of one view still depends on exactly one stored residual block: the dependency cone
does not grow with anything.
"""
from __future__ import annotations

import numpy as np


def dcp_clusters(rows: int, cols: int, positions: np.ndarray):
    """3×3 grid clusters: (parent (N0,) cluster id, key (n_top,) key-view index, offsets (N0, 2))."""
    r, c = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
    nc = -(-cols // 3)
    par = ((r // 3) * nc + (c // 3)).reshape(-1)
    n_top = int(par.max()) + 1
    key = np.zeros(n_top, dtype=np.int64)
    rr, cc = r.reshape(-1), c.reshape(-1)
    for k in range(n_top):                                   # a handful of clusters
        members = np.flatnonzero(par == k)
        cy, cx = rr[members].mean(), cc[members].mean()
        key[k] = members[np.argmin((rr[members] - cy) ** 2 + (cc[members] - cx) ** 2)]
    offsets = np.stack([rr - rr[key[par]], cc - cc[key[par]]], axis=1).astype(np.int64)
    return par.astype(np.int64), key, offsets


def predict_blocks(top: np.ndarray, key_of: np.ndarray, offsets: np.ndarray, disp: np.ndarray,
                   views: np.ndarray, by: np.ndarray, bx: np.ndarray, B: int, nbx: int) -> np.ndarray:
    """Predicted planes of many (view, block) requests.

    Args:
        top: (n_top, Hp, Wp, P) int32 decoded key-view planes.
        key_of: (N0,) cluster of each view; offsets: (N0, 2) grid offset (oy, ox) to the key view.
        disp: (n_top, n_loc) int disparities (pixels per view step).
        views, by, bx: (M,) requests.

    Returns:
        (M, B·B, P) int32.
    """
    hp, wp = top.shape[1:3]
    k = key_of[views]
    d = disp[k, by * nbx + bx]                                           # (M,)
    ys = np.clip(by[:, None] * B + np.arange(B) + (d * offsets[views, 0])[:, None], 0, hp - 1)   # (M, B)
    xs = np.clip(bx[:, None] * B + np.arange(B) + (d * offsets[views, 1])[:, None], 0, wp - 1)
    out = top[k[:, None, None], ys[:, :, None], xs[:, None, :]]          # (M, B, B, P)
    return out.reshape(len(views), B * B, top.shape[3])


def predict_views(top: np.ndarray, key_of: np.ndarray, offsets: np.ndarray, disp: np.ndarray,
                  views: np.ndarray, B: int) -> np.ndarray:
    """Predicted planes of whole views: (n, Hp, Wp, P) int32 (same pixels as predict_blocks)."""
    hp, wp = top.shape[1:3]
    nby, nbx = hp // B, wp // B
    out = np.empty((len(views), hp, wp, top.shape[3]), dtype=top.dtype)
    yy, xx = np.arange(hp), np.arange(wp)
    for i, v in enumerate(np.asarray(views).tolist()):                  # one gather per view
        k = key_of[v]
        dpx = np.repeat(np.repeat(disp[k].reshape(nby, nbx), B, 0), B, 1)    # (Hp, Wp)
        ys = np.clip(yy[:, None] + dpx * offsets[v, 0], 0, hp - 1)
        xs = np.clip(xx[None, :] + dpx * offsets[v, 1], 0, wp - 1)
        out[i] = top[k][ys, xs]
    return out


def estimate(target: np.ndarray, top: np.ndarray, key_of: np.ndarray, offsets: np.ndarray, B: int,
             max_disparity: int, weights: np.ndarray) -> np.ndarray:
    """Per (cluster, block) integer disparity in [-D, D] minimizing the cluster's weighted SSE.

    Args:
        target: (N0, Hp, Wp, P) int32 planes of the views; top: decoded key-view planes.

    Returns:
        (n_top, nby·nbx) int64 disparities.
    """
    n0, hp, wp, P = target.shape
    nby, nbx = hp // B, wp // B
    n_top = top.shape[0]
    cands = np.arange(-max_disparity, max_disparity + 1)
    cost = np.zeros((len(cands), n_top, nby * nbx))
    for j, d in enumerate(cands.tolist()):                              # 2D+1 candidate shifts
        flat = np.full((n_top, nby * nbx), d, dtype=np.int64)
        for a in range(0, n0, 9):
            vs = np.arange(a, min(a + 9, n0))
            pred = predict_views(top, key_of, offsets, flat, vs, B)
            err = (target[vs].astype(np.float32) - pred) ** 2 @ weights.astype(np.float32)   # (n, Hp, Wp)
            e = err.reshape(len(vs), nby, B, nbx, B).sum(axis=(2, 4)).reshape(len(vs), -1)
            np.add.at(cost[j], key_of[vs], e)
    best = np.argmin(cost, axis=0)
    # ties (flat or occluded blocks): prefer the smallest |d|
    zero = cost[max_disparity]
    best = np.where(cost[best, np.arange(n_top)[:, None], np.arange(nby * nbx)[None]] < zero, best, max_disparity)
    return cands[best]
