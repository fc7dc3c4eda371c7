"""Grid scenes: a folder with a ``scene.json`` naming a view pattern (see shared data README)."""
from __future__ import annotations

import json
from pathlib import Path


from ..errors import SceneError
from ..lightfield import LightField, grid_positions
from .common import load_views


def read_grid(folder: Path, baseline: float | None = None, focal: float | None = None) -> LightField:
    """Read ``folder/scene.json`` (layout "grid", rows, cols, views pattern, baseline, focal_px).

    Unknown baseline/focal (null) default to unit baseline and focal = max(H, W) pixels; the
    assumption is recorded in ``meta["assumed"]``. ``baseline``/``focal`` override the file.
    """
    try:
        cfg = json.loads((folder / "scene.json").read_text())
    except (OSError, ValueError) as e:
        raise SceneError(f"{folder / 'scene.json'}: not valid JSON ({e})") from None
    try:
        rows, cols, pattern = int(cfg["rows"]), int(cfg["cols"]), str(cfg["views"])
    except (KeyError, TypeError, ValueError) as e:
        raise SceneError(f"{folder / 'scene.json'}: needs rows, cols and views ({e})") from None
    if cfg.get("layout", "grid") != "grid" or rows < 1 or cols < 1:
        raise SceneError(f"{folder / 'scene.json'}: expected layout 'grid' with rows, cols >= 1")
    try:
        paths = [folder / pattern.format(row=r, col=c) for r in range(rows) for c in range(cols)]
    except (KeyError, IndexError, ValueError) as e:
        raise SceneError(f"{folder / 'scene.json'}: bad views pattern {pattern!r} ({e})") from None
    views = load_views(paths, str(folder))
    views = views.reshape(rows, cols, *views.shape[1:])
    assumed = []
    b = cfg.get("baseline") if baseline is None else baseline
    if b is None:
        b, _ = (1.0, 1.0), assumed.append("baseline=1")
    elif isinstance(b, (int, float)):
        b = (float(b), float(b))
    f = cfg.get("focal_px") if focal is None else focal
    if f is None:
        f = float(max(views.shape[2:4]))
        assumed.append("focal_px=max(H,W)")
    return LightField(views=views, positions=grid_positions(rows, cols, tuple(b)), focal=(float(f), float(f)),
                      layout="grid", meta={"reader": "grid", "source": str(cfg.get("source", "")),
                                           "license": str(cfg.get("license", "")), "assumed": assumed})
