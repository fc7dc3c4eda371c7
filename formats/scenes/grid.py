"""Grid scenes: a folder with a ``scene.json`` naming a view pattern (see shared data README)."""
from __future__ import annotations

import json
import re
import string
from pathlib import Path

from ..errors import SceneError
from ..lightfield import LightField, grid_positions
from ..viewnames import relative_names
from .common import ReadOptions, as_grid, check_count, confine, load_views, number

_SPEC = re.compile(r"^0?\d{0,2}d?$")          # {row:02d}, {col:d}, {row} … nothing wider than 99


def check_pattern(pattern: str, where: str) -> None:
    """A views pattern may use only ``{row}`` and ``{col}`` with small integer formats."""
    try:
        fields = [f for _, f, spec, conv in string.Formatter().parse(pattern) if f is not None]
        specs = [(f, spec, conv) for _, f, spec, conv in string.Formatter().parse(pattern) if f is not None]
    except ValueError as e:
        raise SceneError(f"{where}: bad views pattern {pattern!r} ({e})") from None
    for f, spec, conv in specs:
        if f not in ("row", "col") or conv is not None or not _SPEC.match(spec or ""):
            raise SceneError(f"{where}: views pattern {pattern!r} may only use {{row}} and {{col}} with integer "
                             f"formats like {{row:02d}} (found {{{f}{'!' + conv if conv else ''}"
                             f"{':' + spec if spec else ''}}})")
    if not fields:
        raise SceneError(f"{where}: views pattern {pattern!r} names no {{row}}/{{col}} field")


def read_grid(folder: Path, baseline: float | None = None, focal: float | None = None,
              opts: ReadOptions = ReadOptions()) -> LightField:
    """Read ``folder/scene.json`` (layout "grid", rows, cols, views pattern, baseline, focal_px).

    Unknown baseline/focal (null) default to unit baseline and focal = max(H, W) pixels; the
    assumption is recorded in ``meta["assumed"]``. ``baseline``/``focal`` override the file.
    """
    where = str(folder / "scene.json")
    try:
        cfg = json.loads((folder / "scene.json").read_text())
    except (OSError, ValueError, RecursionError) as e:
        raise SceneError(f"{where}: not valid JSON ({e})") from None
    if not isinstance(cfg, dict):
        raise SceneError(f"{where}: expected a JSON object")
    rows, cols, pattern = cfg.get("rows"), cfg.get("cols"), cfg.get("views")
    if not all(isinstance(x, int) and not isinstance(x, bool) for x in (rows, cols)) \
            or not isinstance(pattern, (str, list)):
        raise SceneError(f"{where}: needs rows, cols and views (integer rows and cols; views: a pattern string or "
                         f"a list of rows*cols file names, row-major)")
    if cfg.get("layout", "grid") != "grid" or rows < 1 or cols < 1:
        raise SceneError(f"{where}: expected layout 'grid' with rows, cols >= 1")
    check_count(rows * cols, where, opts)
    if isinstance(pattern, list):
        if len(pattern) != rows * cols or not all(isinstance(x, str) and x for x in pattern):
            raise SceneError(f"{where}: views lists {len(pattern)} entries; expected {rows * cols} file names")
        names = pattern
    else:
        check_pattern(pattern, where)
        names = [pattern.format(row=r, col=c) for r in range(rows) for c in range(cols)]
    paths = [confine(folder / n, folder, opts, where) for n in names]
    views = as_grid(load_views(paths, str(folder), opts, lazy=opts.lazy), rows, cols)
    assumed = []
    b = cfg.get("baseline") if baseline is None else baseline
    if b is None:
        b, _ = (1.0, 1.0), assumed.append("baseline=1")
    elif isinstance(b, (list, tuple)) and len(b) == 2:
        b = (number(b[0], f"{where}: baseline[0]"), number(b[1], f"{where}: baseline[1]"))
    else:
        v = number(b, f"{where}: baseline")
        b = (v, v)
    f = cfg.get("focal_px") if focal is None else focal
    if f is None:
        f = float(max(views.shape[2:4]))
        assumed.append("focal_px=max(H,W)")
    f = number(f, f"{where}: focal_px", positive=True)
    return LightField(views=views, positions=grid_positions(rows, cols, tuple(b)), focal=(f, f),
                      layout="grid", meta={"reader": "grid", "view_names": relative_names(paths, folder),
                                           "source": str(cfg.get("source", ""))[:2000],
                                           "license": str(cfg.get("license", ""))[:2000], "assumed": assumed,
                                           "input_paths": [str(p.resolve()) for p in paths] + [str((folder / "scene.json").resolve())]})


def _natural_key(p: Path):
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", p.name)]


def read_image_folder(folder: Path, grid: tuple[int, int], baseline: float | None = None,
                      focal: float | None = None, opts: ReadOptions = ReadOptions()) -> LightField:
    """A plain folder of images as a rows × cols grid: files in natural name order
    (``img2`` before ``img10``), row-major. Baseline 1 and focal max(H, W) px unless given."""
    rows, cols = grid
    where = str(folder)
    if rows < 1 or cols < 1:
        raise SceneError(f"{where}: --grid needs rows and cols >= 1, got {rows}x{cols}")
    check_count(rows * cols, where, opts)
    from .common import is_image

    files = sorted((p for p in folder.iterdir() if is_image(p)), key=_natural_key)
    if len(files) != rows * cols:
        raise SceneError(f"{where}: --grid {rows}x{cols} needs {rows * cols} images, the folder has {len(files)}")
    paths = [confine(p, folder, opts, where) for p in files]
    views = as_grid(load_views(paths, where, opts, lazy=opts.lazy), rows, cols)
    assumed = []
    if baseline is None:
        baseline = 1.0
        assumed.append("baseline=1")
    if focal is None:
        focal = float(max(views.shape[2:4]))
        assumed.append("focal_px=max(H,W)")
    b = number(baseline, f"{where}: baseline")
    f = number(focal, f"{where}: focal", positive=True)
    return LightField(views=views, positions=grid_positions(rows, cols, (b, b)), focal=(f, f), layout="grid",
                      meta={"reader": "folder", "assumed": assumed, "files": [p.name for p in files],
                            "view_names": relative_names(paths, folder),
                            "input_paths": [str(p.resolve()) for p in paths]})
