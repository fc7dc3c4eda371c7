"""Helpers shared by the scene readers: confining paths to the scene, bounded loading of a
list of image files into one array, and typed number parsing."""
from __future__ import annotations

import math
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Callable
from pathlib import Path

import numpy as np

from ..errors import SceneError
from ..imageio import IMAGE_EXTENSIONS, image_size, native_stderr, read_image
from ..limits import DEFAULT, Limits


@dataclass(frozen=True)
class ReadOptions:
    """How a scene may be read.

    Attributes:
        limits: caps on views and pixels per view, checked before pixels are read.
        allow_outside: read files that lie outside the scene folder (``..``, absolute paths,
            symlinks leading out). Off by default: a scene file from elsewhere must not pull in
            arbitrary images from the host.
        progress: ``progress(stage, done, total)`` as views are decoded (the CLI's bars), or None.
    """

    limits: Limits = DEFAULT
    allow_outside: bool = False
    progress: Callable[[str, int, int], None] | None = field(default=None, compare=False)


NPY_MAGIC = b"\x93NUMPY"


def open_npy(p: Path, what: str) -> np.ndarray:
    """A ``.npy`` file memory-mapped read-only (nothing is read or allocated beyond its header
    until used: the caller checks the shape first), or a SceneError saying what it is instead:
    not a NumPy file, Python objects (pickled data, never loaded), or a file shorter than its
    header's shape."""
    try:
        with open(p, "rb") as f:
            head = f.read(len(NPY_MAGIC))
    except OSError as e:
        raise SceneError(f"{p}: cannot read {what} ({e.strerror or e})") from None
    if head != NPY_MAGIC:
        raise SceneError(f"{p}: not a NumPy .npy file (no NumPy header); {what} must be saved with numpy.save")
    try:
        return np.load(p, mmap_mode="r", allow_pickle=False)
    except ValueError as e:
        if "pickle" in str(e) or "bject" in str(e):
            raise SceneError(f"{p}: holds Python objects (pickled data), which lfcodec does not load; save "
                             f"{what} as a numeric array") from None
        if "mmap length" in str(e):
            raise SceneError(f"{p}: shorter than the array its .npy header describes (truncated?)") from None
        raise SceneError(f"{p}: not a readable .npy array ({e})") from None
    except (OSError, EOFError) as e:
        raise SceneError(f"{p}: not a readable .npy array ({type(e).__name__}: {e})") from None


def is_image(p: Path) -> bool:
    return p.suffix.lower() in IMAGE_EXTENSIONS and p.is_file() and not p.name.startswith(".")


def confine(path: Path, root: Path, opts: ReadOptions, what: str) -> Path:
    """``path`` if it resolves (symlinks followed) inside ``root``, else a SceneError (unless
    the options allow paths outside the scene)."""
    try:
        res = path.resolve()
        top = root.resolve()
    except (OSError, RuntimeError) as e:
        raise SceneError(f"{what}: cannot resolve {path} ({e})") from None
    if not opts.allow_outside and res != top and top not in res.parents:
        raise SceneError(f"{what}: {path} lies outside the scene folder {root} (refused; "
                         "pass --allow-outside-paths to read it)")
    return path


def check_count(n: int, what: str, opts: ReadOptions) -> None:
    if n > opts.limits.max_views:
        raise SceneError(f"{what}: {n} views exceed the limit of {opts.limits.max_views}")


def number(v, what: str, *, positive: bool = False) -> float:
    """A finite float from a JSON/config value, or a SceneError naming ``what``."""
    try:
        x = float(v)
    except (TypeError, ValueError):
        raise SceneError(f"{what} must be a number, got {v!r}") from None
    if not math.isfinite(x) or (positive and x <= 0):
        raise SceneError(f"{what} must be a finite{' positive' if positive else ''} number, got {v!r}")
    return x


def load_views(paths: list[Path], what: str, opts: ReadOptions = ReadOptions()) -> np.ndarray:
    """Read image files that must all share size, channels and depth.

    Every header is read first (sizes, channels, depth checked against each other and the
    limits) before any pixel is decoded.

    Args:
        paths: image files in view order.
        what: the scene's name for messages.

    Returns:
        (N, H, W, C) array in the files' common dtype.

    Raises:
        SceneError: a missing or unreadable file, or files that disagree in size/channels/depth
            or exceed the limits.
    """
    if not paths:
        raise SceneError(f"{what}: no views found")
    check_count(len(paths), what, opts)
    for p in paths:
        if not os.path.isfile(p):
            raise SceneError(f"{what}: missing view {p}")
    heads = [image_size(p) for p in paths]
    h, w, c, fmt = heads[0]
    if h * w > opts.limits.max_view_pixels:
        raise SceneError(f"{what}: views of {h}x{w} pixels exceed the limit of {opts.limits.max_view_pixels}")
    if len(paths) * h * w > opts.limits.max_scene_pixels:
        raise SceneError(f"{what}: {len(paths)} views of {h}x{w} pixels exceed the limit of "
                         f"{opts.limits.max_scene_pixels} pixels per scene")
    for p, hd in zip(paths, heads):
        if hd != heads[0]:
            raise SceneError(
                f"{what}: view {p.name} is {hd[0]}x{hd[1]}x{hd[2]} {hd[3]}, but {paths[0].name} is "
                f"{h}x{w}x{c} {fmt}; all views must share size, channels and bit depth")
    workers = min(4, len(paths))
    imgs = []
    with native_stderr(), ThreadPoolExecutor(workers) as ex:
        for im in ex.map(lambda p: read_image(p, opts.limits.max_view_pixels), paths):
            imgs.append(im)
            if opts.progress is not None:
                opts.progress("read views", len(imgs), len(paths))
    first = imgs[0]
    for p, im in zip(paths, imgs):
        if im.shape != first.shape or im.dtype != first.dtype:
            raise SceneError(f"{what}: view {p.name} decodes to {im.shape} {im.dtype}, but {paths[0].name} to "
                             f"{first.shape} {first.dtype}")
    return np.stack(imgs)
