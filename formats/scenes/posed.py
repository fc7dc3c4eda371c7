"""Posed, unordered captures: LLFF (``images/`` + ``poses_bounds.npy``) and
nerfstudio / instant-ngp / NeRF-synthetic ``transforms.json``. Both become a 1 × N light
field with per-view OpenGL camera-to-world matrices."""
from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np

from ..errors import SceneError
from ..imageio import IMAGE_EXTENSIONS
from ..lightfield import LightField
from ..viewnames import relative_names
from .common import ReadOptions, check_count, confine, is_image, load_views, number, open_npy


def read_llff(folder: Path, opts: ReadOptions = ReadOptions()) -> LightField:
    """Read an LLFF capture.

    ``poses_bounds.npy`` is (N, 17): a row-major 3×5 ``[R | t | hwf]`` per view (LLFF axes:
    down, right, backwards) then near/far. hwf is for the original capture; the focal length is
    rescaled to the stored images' width.
    """
    pb_path = folder / "poses_bounds.npy"
    pb = open_npy(pb_path, "the camera poses")
    if pb.ndim != 2 or pb.shape[1] != 17 or pb.dtype.kind not in "fiu":
        raise SceneError(f"{pb_path}: expected an N x 17 numeric array, got shape {pb.shape} {pb.dtype}")
    check_count(pb.shape[0], str(pb_path), opts)
    pb = np.array(pb, dtype=np.float64)          # read only now that its size is known
    if not np.isfinite(pb).all():
        raise SceneError(f"{pb_path}: holds NaN or infinite values")
    img_dir = folder / "images"
    files = sorted(p for p in img_dir.iterdir() if is_image(p)) if img_dir.is_dir() else []
    if len(files) != pb.shape[0]:
        raise SceneError(f"{folder}: poses_bounds.npy has {pb.shape[0]} poses but images/ has {len(files)} images")
    files = [confine(p, folder, opts, str(folder)) for p in files]
    views = load_views(files, str(folder), opts)
    n, h, w = views.shape[:3]
    m = pb[:, :15].reshape(n, 3, 5)
    if (m[:, :, 4][:, :3] <= 0).any():
        raise SceneError(f"{pb_path}: height, width and focal (the hwf column) must be positive")
    rot_llff, t, hwf = m[:, :, :3], m[:, :, 3], m[:, :, 4]
    rot = np.stack([rot_llff[:, :, 1], -rot_llff[:, :, 0], rot_llff[:, :, 2]], axis=-1)
    c2w = np.tile(np.eye(4), (n, 1, 1))
    c2w[:, :3, :3] = rot
    c2w[:, :3, 3] = t
    f = float(hwf[0, 2]) * w / float(hwf[0, 1])
    return LightField(views=views[None], positions=t[None], c2w=c2w[None], focal=(f, f), layout="posed",
                      meta={"reader": "llff", "files": [p.name for p in files], "view_names": relative_names(files, folder),
                            "bounds": np.round(pb[:, 15:], 6).tolist(),
                            "input_paths": [str(p.resolve()) for p in files] + [str(pb_path.resolve())]})


def _frame_file(base: Path, file_path: str) -> Path:
    p = base / file_path
    if p.suffix.lower() in IMAGE_EXTENSIONS:
        return p
    for ext in (".png", ".jpg", ".jpeg", ".exr", ".tif"):
        if p.with_name(p.name + ext).is_file():
            return p.with_name(p.name + ext)
    return p.with_name(p.name + ".png")


def read_transforms(path: Path, opts: ReadOptions = ReadOptions()) -> LightField:
    """Read a ``transforms.json`` (nerfstudio, instant-ngp, NeRF synthetic).

    Intrinsics from ``fl_x``/``fl_y`` or ``camera_angle_x``/``camera_angle_y``, ``cx``/``cy``
    (default: image centre); ``frames[].transform_matrix`` is an OpenGL camera-to-world.
    """
    try:
        cfg = json.loads(path.read_text())
    except (OSError, ValueError, RecursionError) as e:
        raise SceneError(f"{path}: not valid JSON ({e})") from None
    frames = cfg.get("frames") if isinstance(cfg, dict) else None
    if not isinstance(frames, list) or not frames:
        raise SceneError(f"{path}: not a transforms.json with a non-empty frames list")
    check_count(len(frames), str(path), opts)
    if not all(isinstance(fr, dict) and isinstance(fr.get("file_path"), str) for fr in frames):
        raise SceneError(f"{path}: every frame needs a file_path string")
    files = [confine(_frame_file(path.parent, fr["file_path"]), path.parent, opts, str(path)) for fr in frames]
    # the cameras are checked before any view is read (a bad matrix used to wait for every image)
    missing = [i for i, fr in enumerate(frames) if "transform_matrix" not in fr]
    if missing:
        raise SceneError(f"{path}: frame {missing[0]} has no transform_matrix")
    try:
        c2w = np.asarray([fr["transform_matrix"] for fr in frames], dtype=np.float64)
    except (ValueError, TypeError):
        raise SceneError(f"{path}: transform_matrix must be 4x4 numbers in every frame") from None
    if c2w.shape != (len(frames), 4, 4):
        raise SceneError(f"{path}: transform_matrix must be 4x4 per frame, got {c2w.shape[1:]}")
    if not np.isfinite(c2w).all():
        raise SceneError(f"{path}: a transform_matrix holds NaN or infinite values")
    views = load_views(files, str(path), opts)
    n, h, w = views.shape[:3]
    if "fl_x" in cfg:
        fx = number(cfg["fl_x"], f"{path}: fl_x", positive=True)
        fy = number(cfg.get("fl_y", fx), f"{path}: fl_y", positive=True)
    elif "camera_angle_x" in cfg:
        ax = number(cfg["camera_angle_x"], f"{path}: camera_angle_x", positive=True)
        if ax >= math.pi:
            raise SceneError(f"{path}: camera_angle_x must be below pi radians, got {ax}")
        fx = 0.5 * w / math.tan(0.5 * ax)
        fy = fx
        if "camera_angle_y" in cfg:
            ay = number(cfg["camera_angle_y"], f"{path}: camera_angle_y", positive=True)
            if ay >= math.pi:
                raise SceneError(f"{path}: camera_angle_y must be below pi radians, got {ay}")
            fy = 0.5 * h / math.tan(0.5 * ay)
    else:
        raise SceneError(f"{path}: needs fl_x or camera_angle_x")
    cx = number(cfg.get("cx", w / 2.0), f"{path}: cx")
    cy = number(cfg.get("cy", h / 2.0), f"{path}: cy")
    return LightField(views=views[None], positions=c2w[None, :, :3, 3], c2w=c2w[None], focal=(fx, fy),
                      principal=(cx, cy), layout="posed",
                      meta={"reader": "transforms", "files": [os.path.relpath(f, path.parent) for f in files],
                            "view_names": relative_names(files, path.parent),
                            "input_paths": [str(f.resolve()) for f in files] + [str(path.resolve())]})


SPLIT_ORDER = ("train", "val", "test")


def read_transform_splits(folder: Path, opts: ReadOptions = ReadOptions()) -> LightField:
    """Every ``transforms_<split>.json`` of a folder as one posed capture (train, val, test, then
    other splits by name). The splits must share view size, channels, depth and intrinsics; the
    light field records them (``meta["splits"]``: [(name, views)] in view order), so a decode
    writes each split back to its own file."""
    names = [q.name[len("transforms_"):-len(".json")] for q in folder.glob("transforms_*.json") if q.is_file()]
    names = sorted(names, key=lambda n: (SPLIT_ORDER.index(n) if n in SPLIT_ORDER else len(SPLIT_ORDER), n))
    if not names:
        raise SceneError(f"{folder}: no transforms_<split>.json files")
    parts, total = [], 0
    for n in names:
        lf = read_transforms(folder / f"transforms_{n}.json", opts)
        total += lf.cols
        check_count(total, str(folder), opts)
        if total * lf.height * lf.width > opts.limits.max_scene_pixels:
            raise SceneError(f"{folder}: {total} views of {lf.height}x{lf.width} pixels exceed the limit of "
                             f"{opts.limits.max_scene_pixels} pixels per scene")
        if parts:
            a = parts[0][1]
            if lf.views.shape[2:] != a.views.shape[2:] or lf.views.dtype != a.views.dtype:
                raise SceneError(f"{folder}: split '{n}' has views of {lf.views.shape[2:]} {lf.views.dtype}, split "
                                 f"'{parts[0][0]}' {a.views.shape[2:]} {a.views.dtype}; --split all needs them equal")
            if not (np.allclose(lf.focal, a.focal, rtol=1e-6) and np.allclose(lf.principal, a.principal, rtol=1e-6)):
                raise SceneError(f"{folder}: split '{n}' has other camera intrinsics than split '{parts[0][0]}'; "
                                 f"--split all needs one camera model")
        parts.append((n, lf))
    first = parts[0][1]

    def cat(key):
        return [x for _, lf in parts for x in lf.meta[key]]

    return LightField(views=np.concatenate([lf.views for _, lf in parts], 1),
                      positions=np.concatenate([lf.positions for _, lf in parts], 1),
                      c2w=np.concatenate([lf.c2w for _, lf in parts], 1), focal=first.focal, principal=first.principal,
                      layout="posed",
                      meta={"reader": "transforms", "files": cat("files"), "view_names": cat("view_names"),
                            "input_paths": cat("input_paths"), "splits": [(n, lf.cols) for n, lf in parts]})


def plucker_rays(lf: LightField, row: int, col: int) -> tuple[np.ndarray, np.ndarray]:
    """Per-pixel rays of one view: origins and unit directions, both (H, W, 3) float64.

    Pixel centres at +0.5; OpenGL camera (x right, y up, -z forward). Grid scenes without
    matrices use an identity rotation at the view's position.
    """
    h, w = lf.height, lf.width
    c2w = lf.c2w[row, col] if lf.c2w is not None else np.eye(4)
    if lf.c2w is None:
        c2w = c2w.copy()
        c2w[:3, 3] = lf.positions[row, col]
    ys, xs = np.meshgrid(np.arange(h) + 0.5, np.arange(w) + 0.5, indexing="ij")
    d = np.stack([(xs - lf.principal[0]) / lf.focal[0], -(ys - lf.principal[1]) / lf.focal[1], -np.ones_like(xs)], -1)
    d = d @ c2w[:3, :3].T
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    o = np.broadcast_to(c2w[:3, 3], d.shape).copy()
    return o, d
