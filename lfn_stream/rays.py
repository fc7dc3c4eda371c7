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
        ys, xs = np.meshgrid(np.arange(h) + 0.5, np.arange(w) + 0.5, indexing="ij")
    else:
        ys, xs = np.divmod(np.asarray(at, np.int64), w)
        ys, xs = ys + 0.5, xs + 0.5
    with np.errstate(all="ignore"):          # checked below: a ray that is not finite is an error
        d = np.stack([(xs - cx) / fx, -(ys - cy) / fy, -np.ones_like(xs)], -1) @ c2w[:3, :3].T
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
        o = (c2w[:3, 3] - np.asarray(centre)) / radius
        m = np.cross(np.broadcast_to(o, d.shape), d)
        rays = np.concatenate([d, m], -1).astype(np.float32)
    if not np.isfinite(rays).all():
        raise ParameterError("the camera's rays are not finite in float32 (focal length, pose or scene scale "
                             "out of range)")
    return rays
