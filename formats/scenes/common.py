"""Helpers shared by the scene readers: loading a list of image files into one array."""
from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from ..errors import SceneError
from ..imageio import IMAGE_EXTENSIONS, read_image


def is_image(p: Path) -> bool:
    return p.suffix.lower() in IMAGE_EXTENSIONS and p.is_file() and not p.name.startswith(".")


def load_views(paths: list[Path], what: str) -> np.ndarray:
    """Read image files that must all share size, channels and depth.

    Args:
        paths: image files in view order.
        what: the scene's name for messages.

    Returns:
        (N, H, W, C) array in the files' common dtype.

    Raises:
        SceneError: a missing or unreadable file, or files that disagree in size/channels/depth.
    """
    if not paths:
        raise SceneError(f"{what}: no views found")
    for p in paths:
        if not os.path.isfile(p):
            raise SceneError(f"{what}: missing view {p}")
    workers = min(4, len(paths))
    with ThreadPoolExecutor(workers) as ex:
        imgs = list(ex.map(read_image, paths))
    first = imgs[0]
    for p, im in zip(paths, imgs):
        if im.shape != first.shape or im.dtype != first.dtype:
            raise SceneError(
                f"{what}: view {p.name} is {im.shape[1]}x{im.shape[0]}x{im.shape[2]} {im.dtype}, "
                f"but {paths[0].name} is {first.shape[1]}x{first.shape[0]}x{first.shape[2]} {first.dtype}; "
                "all views must share size, channels and bit depth")
    return np.stack(imgs)
