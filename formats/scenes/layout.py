"""Layout files for decoded views, so that a decoded folder reads back as the same scene:
``scene.json`` for a regular grid, ``transforms.json`` (OpenGL camera-to-world poses, pixel
intrinsics) for anything else — the formats :func:`formats.scenes.read_scene` reads."""
from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from ..lightfield import read_geometry


def _atomic_write(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    tmp.write_text(text)
    os.replace(tmp, path)


def layout_paths(folder: str | os.PathLike, geometry: dict) -> list[Path]:
    """The layout file(s) :func:`write_layout` writes in ``folder`` for ``geometry``."""
    folder = Path(folder)
    g = read_geometry(geometry, "scene")
    if "baseline" in g and g["layout"] == "grid" and "c2w" not in g:
        return [folder / "scene.json"]
    if "splits" in g:
        return [folder / f"transforms_{name}.json" for name, _ in g["splits"]]
    return [folder / "transforms.json"]


def written_by_lfcodec(path: str | os.PathLike) -> bool:
    """Whether the layout file ``path`` is one :func:`write_layout` wrote (its ``source`` says so)."""
    try:
        doc = json.loads(Path(path).read_text())
    except (OSError, ValueError, UnicodeDecodeError):
        return False
    return isinstance(doc, dict) and doc.get("source") == SOURCE


SOURCE = "decoded by lfcodec"


def write_layout(folder: str | os.PathLike, geometry: dict, filename) -> Path:
    """Write the layout file of views saved as ``filename(row, col)`` in ``folder``.

    Args:
        geometry: a file's scene geometry (:meth:`formats.lightfield.LightField.geometry`).
        filename: (row, col) → the view's file name inside ``folder``.

    Returns:
        the path written (``scene.json`` or ``transforms.json``; the first ``transforms_<split>.json``
        when the geometry records splits, one file per split).
    """
    folder = Path(folder)
    g = read_geometry(geometry, "scene")
    rows, cols = g["rows"], g["cols"]
    fx, fy = g["focal"]
    if "baseline" in g and g["layout"] == "grid" and "c2w" not in g:
        pattern = filename(0, 0).replace("00", "{row:02d}", 1).replace("00", "{col:02d}", 1)
        if any(pattern.format(row=r, col=c) != filename(r, c) for r in range(rows) for c in range(cols)):
            pattern = [filename(r, c) for r in range(rows) for c in range(cols)]      # names, row-major
        doc = {"layout": "grid", "rows": rows, "cols": cols, "views": pattern,
               "baseline": g["baseline"], "focal_px": fx, "source": SOURCE}
        path = folder / "scene.json"
    else:
        if "c2w" in g:
            c2w = g["c2w"]
        else:                                   # positions only: parallel cameras looking down −z
            c2w = np.tile(np.eye(4), (rows, cols, 1, 1))
            c2w[..., :3, 3] = g["positions"]
        cx, cy = g.get("principal", (g["width"] / 2.0, g["height"] / 2.0))
        frames = [{"file_path": filename(r, c), "transform_matrix": np.round(c2w[r, c], 9).tolist()}
                  for r in range(rows) for c in range(cols)]
        head = {"fl_x": fx, "fl_y": fy, "cx": cx, "cy": cy, "w": g["width"], "h": g["height"]}
        if "splits" in g:               # one transforms_<split>.json per recorded split, frames in order
            start, paths = 0, []
            for name, n in g["splits"]:
                doc = {**head, "frames": frames[start:start + n], "source": SOURCE}
                paths.append(folder / f"transforms_{name}.json")
                _atomic_write(paths[-1], json.dumps(doc, indent=1, allow_nan=False) + "\n")
                start += n
            return paths[0]
        doc = {**head, "frames": frames, "source": SOURCE}
        path = folder / "transforms.json"
    _atomic_write(path, json.dumps(doc, indent=1, allow_nan=False) + "\n")
    return path
