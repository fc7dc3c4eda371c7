"""Free cameras for a light field network: a pose anywhere, not only the captured ones.

A pose is a 4×4 camera-to-world matrix (OpenGL camera: x right, y up, looking down −z), in the
scene's units. Three ways to make one from a file's cameras, the same formulas as the browser
viewer (formats/web/lfn.js), so both show the same view:

- :func:`grid_pose`: a continuous grid position (s, t) in view units; the centre is the bilinear
  blend of the four captured centres around it, the rotation that of the nearest view.
- :func:`orbit_pose`: a captured view turned about a pivot — ``yaw`` degrees about the scene's
  up axis, then ``pitch`` degrees about the camera's right axis (360° captures).
- :func:`stereo_poses`: a left/right pair, the centres ``ipd`` scene units apart along the
  camera's x axis.
"""
from __future__ import annotations

import numpy as np

from formats.errors import ParameterError


def captured_poses(positions: np.ndarray, c2w: np.ndarray | None) -> np.ndarray:
    """(R, C, 4, 4) poses of the captured views (identity rotations where only centres are known)."""
    if c2w is not None:
        return np.asarray(c2w, np.float64)
    pos = np.asarray(positions, np.float64)
    out = np.broadcast_to(np.eye(4), pos.shape[:2] + (4, 4)).copy()
    out[..., :3, 3] = pos
    return out


def grid_pose(poses: np.ndarray, s: float, t: float) -> np.ndarray:
    """Pose at grid position (row s, column t), both continuous and inside the grid."""
    R, C = poses.shape[:2]
    if not (np.isfinite(s) and np.isfinite(t) and 0 <= s <= R - 1 and 0 <= t <= C - 1):
        raise ParameterError(f"grid position ({s}, {t}) is outside the {R}x{C} grid")
    r0, c0 = min(int(np.floor(s)), R - 1), min(int(np.floor(t)), C - 1)
    r1, c1 = min(r0 + 1, R - 1), min(c0 + 1, C - 1)
    a, b = s - r0, t - c0
    p = ((1 - a) * (1 - b) * poses[r0, c0, :3, 3] + (1 - a) * b * poses[r0, c1, :3, 3]
         + a * (1 - b) * poses[r1, c0, :3, 3] + a * b * poses[r1, c1, :3, 3])
    out = poses[int(np.floor(s + 0.5)), int(np.floor(t + 0.5))].copy()
    out[:3, 3] = p
    return out


def scene_pivot(poses: np.ndarray, fallback) -> tuple[np.ndarray, np.ndarray]:
    """(pivot, up) of a posed capture: the point nearest to every camera's optical axis (least
    squares; ``fallback`` when the axes are near parallel, as on a planar grid) and the unit
    mean of the cameras' up vectors ((0, 1, 0) when they cancel)."""
    P = poses.reshape(-1, 4, 4)
    d = -P[:, :3, 2]
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    o = P[:, :3, 3]
    A = np.eye(3) * len(P) - np.einsum("ni,nj->ij", d, d)
    proj = o - d * np.einsum("ni,ni->n", d, o)[:, None]
    w = np.linalg.eigvalsh(A)
    pivot = np.linalg.solve(A, proj.sum(0)) if w[0] > 1e-3 * max(w[-1], 1e-12) else np.asarray(fallback, np.float64)
    up = P[:, :3, 1].sum(0)
    n = np.linalg.norm(up)
    up = up / n if n > 1e-9 else np.array([0.0, 1.0, 0.0])
    return pivot, up


def _rotation(axis: np.ndarray, deg: float) -> np.ndarray:
    """3×3 rotation by ``deg`` degrees about a unit axis (Rodrigues)."""
    x, y, z = axis
    a = np.deg2rad(deg)
    c, s, k = np.cos(a), np.sin(a), 1 - np.cos(a)
    return np.array([[c + x * x * k, x * y * k - z * s, x * z * k + y * s],
                     [y * x * k + z * s, c + y * y * k, y * z * k - x * s],
                     [z * x * k - y * s, z * y * k + x * s, c + z * z * k]])


def orbit_pose(pose: np.ndarray, pivot, up, yaw: float, pitch: float) -> np.ndarray:
    """``pose`` turned about ``pivot``: ``pitch`` degrees about its own right axis, then ``yaw``
    degrees about ``up`` (both rotations move the centre and the view direction together)."""
    if not (np.isfinite(yaw) and np.isfinite(pitch)):
        raise ParameterError(f"yaw and pitch must be finite degrees, got {yaw}, {pitch}")
    right = pose[:3, 0] / np.linalg.norm(pose[:3, 0])
    M = _rotation(np.asarray(up, np.float64), yaw) @ _rotation(right, pitch)
    out = np.eye(4)
    out[:3, :3] = M @ pose[:3, :3]
    out[:3, 3] = np.asarray(pivot) + M @ (pose[:3, 3] - np.asarray(pivot))
    return out


def stereo_poses(pose: np.ndarray, ipd: float) -> tuple[np.ndarray, np.ndarray]:
    """(left, right) poses, centres ``ipd`` scene units apart along the camera's x axis."""
    if not (np.isfinite(ipd) and ipd >= 0):
        raise ParameterError(f"ipd must be a finite distance >= 0, got {ipd}")
    x = pose[:3, 0] / np.linalg.norm(pose[:3, 0])
    left, right = pose.copy(), pose.copy()
    left[:3, 3] -= x * ipd / 2
    right[:3, 3] += x * ipd / 2
    return left, right
