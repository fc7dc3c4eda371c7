"""Grids given by file names alone: the HCI benchmark (``input_Cam000.png`` …, row-major,
square grid) and the Stanford light field archive (``out_RR_CC_*.png``)."""
from __future__ import annotations

import math
import re
from pathlib import Path

from ..errors import SceneError
from ..lightfield import LightField, grid_positions
from ..viewnames import relative_names
from .common import ReadOptions, as_grid, check_count, confine, is_image, load_views, number

HCI_RE = re.compile(r"^input_Cam(\d{3})\.\w+$")
STANFORD_RE = re.compile(r"^out_(\d+)_(\d+)(_.*)?\.\w+$")


def _parse_cfg(path: Path) -> dict:
    """HCI ``parameters.cfg`` (INI-like ``key = value``)."""
    out = {}
    for line in path.read_text(errors="replace").splitlines():
        if "=" in line and not line.strip().startswith(("#", "[")):
            k, v = line.split("=", 1)
            out[k.strip()] = v.strip()
    return out


def read_hci(folder: Path, baseline: float | None = None, focal: float | None = None,
             opts: ReadOptions = ReadOptions()) -> LightField:
    """Read an HCI 4D light field benchmark folder (views ``input_CamNNN``, row-major).

    The grid is square (9×9 in the benchmark) unless ``parameters.cfg`` says otherwise.
    """
    files = sorted((p for p in folder.iterdir() if HCI_RE.match(p.name) and is_image(p)),
                   key=lambda p: int(HCI_RE.match(p.name).group(1)))
    n = len(files)
    idx = [int(HCI_RE.match(p.name).group(1)) for p in files]
    cfg = _parse_cfg(folder / "parameters.cfg") if (folder / "parameters.cfg").is_file() else {}
    where = str(folder / "parameters.cfg")
    rows = int(number(cfg.get("num_cams_y", 0), f"{where}: num_cams_y")) or int(round(math.sqrt(n)))
    cols = int(number(cfg.get("num_cams_x", 0), f"{where}: num_cams_x")) or rows
    check_count(rows * cols, str(folder), opts)
    if rows * cols != n or idx != list(range(n)):
        missing = sorted(set(range(rows * cols)) - set(idx))
        raise SceneError(f"{folder}: HCI grid {rows}x{cols} needs input_Cam000..{rows * cols - 1:03d}; "
                         f"found {n} views" + (f", missing e.g. input_Cam{missing[0]:03d}" if missing else ""))
    files = [confine(p, folder, opts, str(folder)) for p in files]
    views = as_grid(load_views(files, str(folder), opts, lazy=opts.lazy), rows, cols)
    assumed = []
    f = focal
    if f is None and "focal_length_mm" in cfg and "sensor_size_mm" in cfg:
        f = number(cfg["focal_length_mm"], f"{where}: focal_length_mm", positive=True) / number(
            cfg["sensor_size_mm"], f"{where}: sensor_size_mm", positive=True) * max(views.shape[2:4])
    if f is None:
        f = float(max(views.shape[2:4]))
        assumed.append("focal_px=max(H,W)")
    b = baseline
    if b is None and "baseline_mm" in cfg:
        b = number(cfg["baseline_mm"], f"{where}: baseline_mm")
    if b is None:
        b = 1.0
        assumed.append("baseline=1")
    return LightField(views=views, positions=grid_positions(rows, cols, (b, b)), focal=(f, f), layout="grid",
                      meta={"reader": "hci", "assumed": assumed, "view_names": relative_names(files, folder),
                            "input_paths": [str(p.resolve()) for p in files]})


def read_stanford(folder: Path, baseline: float | None = None, focal: float | None = None,
                  opts: ReadOptions = ReadOptions()) -> LightField:
    """Read a Stanford archive folder (``out_RR_CC_<x>_<y>.png``; RR row, CC column)."""
    items = {}
    for p in folder.iterdir():
        m = STANFORD_RE.match(p.name)
        if m and is_image(p):
            items[(int(m.group(1)), int(m.group(2)))] = p
    rows = max(k[0] for k in items) + 1
    cols = max(k[1] for k in items) + 1
    r0 = min(k[0] for k in items)
    c0 = min(k[1] for k in items)
    rows, cols = rows - r0, cols - c0
    check_count(rows * cols, str(folder), opts)
    if rows * cols > len(items):
        raise SceneError(f"{folder}: Stanford grid {rows}x{cols} is missing views (it has only {len(items)})")
    missing = [(r, c) for r in range(r0, r0 + rows) for c in range(c0, c0 + cols) if (r, c) not in items]
    if missing:
        raise SceneError(f"{folder}: Stanford grid {rows}x{cols} is missing view out_{missing[0][0]:02d}_{missing[0][1]:02d}")
    files = [confine(items[(r, c)], folder, opts, str(folder)) for r in range(r0, r0 + rows) for c in range(c0, c0 + cols)]
    views = as_grid(load_views(files, str(folder), opts, lazy=opts.lazy), rows, cols)
    f = float(focal) if focal else float(max(views.shape[2:4]))
    b = float(baseline) if baseline else 1.0
    return LightField(views=views, positions=grid_positions(rows, cols, (b, b)), focal=(f, f), layout="grid",
                      meta={"reader": "stanford", "assumed": [] if baseline else ["baseline=1"],
                            "view_names": relative_names(files, folder),
                            "input_paths": [str(p.resolve()) for p in files]})
