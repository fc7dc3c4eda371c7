"""Rays of a light field's cameras, as normalized Plücker coordinates.

A ray with origin o and unit direction d is (d, o × d): 6 numbers independent of where on the
ray o lies. Origins are first normalized (o - centre) / radius with the training cameras'
centre and radius, stored in the stream's config.
"""
from __future__ import annotations

import numpy as np

from formats.errors import ParameterError
from formats.lightfield import LightField


def normalization(lf: LightField, views: np.ndarray | None = None) -> tuple[list[float], float]:
    """(centre, radius) of the camera centres (all views, or the given flat indices)."""
    pos = lf.positions.reshape(-1, 3)
    if views is not None:
        pos = pos[views]
    c = pos.mean(0)
    r = float(np.linalg.norm(pos - c, axis=1).max())
    return c.tolist(), (r if r > 0 else 1.0)


def view_rays(lf: LightField, view: int, scale: float = 1.0, centre=(0, 0, 0), radius: float = 1.0,
              size: tuple[int, int] | None = None, spacing: tuple[float, float] | None = None,
              at: np.ndarray | None = None) -> np.ndarray:
    """Plücker rays through the pixel centres of one view rendered at ``scale`` (``size``,
    ``spacing`` and ``at``: as :func:`camera_rays`).

    Returns:
        (h, w, 6) float32 with h, w = round(H·scale), round(W·scale) (or ``size``).
    """
    r, c = divmod(view, lf.cols)
    if lf.c2w is not None:
        c2w = lf.c2w[r, c]
    else:
        c2w = np.eye(4)
        c2w[:3, 3] = lf.positions[r, c]
    return camera_rays(c2w, lf.focal, lf.principal, lf.height, lf.width, scale, centre, radius, size, spacing, at)


def camera_rays(c2w: np.ndarray, focal, principal, H: int, W: int, scale: float = 1.0, centre=(0, 0, 0),
                radius: float = 1.0, size: tuple[int, int] | None = None,
                spacing: tuple[float, float] | None = None, at: np.ndarray | None = None) -> np.ndarray:
    """Plücker rays through the pixel centres of a camera with pose ``c2w`` (4×4, OpenGL axes),
    focal lengths and principal point in pixels of an H×W view, rendered at ``scale``.
    ``spacing`` (sy, sx): output pixels per view pixel along y and x, where they are not
    ``size`` / (H, W) (a lattice every k pixels of a render that a size does not divide).
    ``at``: only the rays of these flat (row-major) pixel indices.

    Returns:
        (h, w, 6) float32 with h, w = round(H·scale), round(W·scale) (or ``size``); with ``at``,
        (len(at), 6).
    """
    h, w = size or (max(1, round(H * scale)), max(1, round(W * scale)))
    sy, sx = spacing or (h / H, w / W)
    fx, fy = focal[0] * sx, focal[1] * sy
    cx, cy = principal[0] * sx, principal[1] * sy
    if at is None:
        ys, xs = (np.arange(h) + 0.5)[:, None], (np.arange(w) + 0.5)[None, :]     # broadcast to (h, w)
    else:
        ys, xs = np.divmod(np.asarray(at, np.int64), w)
        ys, xs = ys + 0.5, xs + 0.5
    R = np.asarray(c2w, np.float64)[:3, :3]
    o = (np.asarray(c2w, np.float64)[:3, 3] - np.asarray(centre, np.float64)) / radius
    rays = np.empty(np.broadcast_shapes(np.shape(ys), np.shape(xs)) + (6,), np.float32)
    with np.errstate(all="ignore"):          # checked below: a ray that is not finite is an error
        # d = R (u, v, −1) / |·|, then o × d: each component written out (no BLAS product, no
        # temporaries of stacked vectors; the browser decoder's lfn.js runs the same operations)
        u, v = (xs - cx) / fx, -(ys - cy) / fy
        d = [np.add(u * R[i, 0], v * R[i, 1]) for i in range(3)]
        n = np.zeros_like(d[0])
        for i in range(3):
            d[i] -= R[i, 2]
            n += d[i] * d[i]
        np.sqrt(n, out=n)
        for i in range(3):
            d[i] /= n
            rays[..., i] = d[i]
        for i, (a, b) in enumerate(((1, 2), (2, 0), (0, 1))):
            x = o[a] * d[b]
            x -= o[b] * d[a]
            rays[..., 3 + i] = x
    if not np.isfinite(rays).all():
        raise ParameterError("the camera's rays are not finite in float32 (focal length, pose or scene scale "
                             "out of range)")
    return rays
