"""Scene readers (one per capture format) and the writer for decoded views.

``read_scene(path)`` detects the layout:

- ``scene.json`` → grid scene (:func:`read_grid`)
- ``poses_bounds.npy`` + ``images/`` → LLFF (:func:`read_llff`)
- ``transforms.json`` / ``transforms_<split>.json`` (or the JSON file itself) → :func:`read_transforms`
- ``input_CamNNN.*`` → HCI benchmark (:func:`read_hci`)
- ``out_RR_CC_*.*`` → Stanford archive (:func:`read_stanford`)
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..errors import SceneError
from ..imageio import write_image
from ..lightfield import LightField
from ..limits import DEFAULT, Limits
from .common import ReadOptions, is_image
from .grid import read_grid, read_image_folder
from .layout import write_layout
from .named import HCI_RE, STANFORD_RE, read_hci, read_stanford
from .posed import plucker_rays, read_llff, read_transform_splits, read_transforms

__all__ = ["read_scene", "write_views", "write_layout", "read_grid", "read_hci", "read_stanford", "read_llff",
           "read_transforms", "read_transform_splits", "plucker_rays", "view_filename"]


def read_npy(p: Path, grid: tuple[int, int] | None, limits: Limits = DEFAULT) -> LightField:
    """An (N, H, W[, C]) or (R, C, H, W, C) ``.npy`` array, memory-mapped and read a view at a
    time (:class:`formats.viewstack.ViewStack`); ``grid`` (rows, cols) for an (N, ...) array
    (default 1 × N). Checked against ``limits`` before any pixel is read."""
    import numpy as np

    from ..viewstack import from_array

    from .common import open_npy

    arr = open_npy(p, "the views")
    if arr.ndim in (3, 4, 5) and arr.dtype in (np.uint8, np.uint16):
        n = int(np.prod(arr.shape[:2])) if arr.ndim == 5 else arr.shape[0]
        hw = int(np.prod(arr.shape[-3:-1])) if arr.ndim != 3 else int(np.prod(arr.shape[1:]))
        if n > limits.max_views or hw > limits.max_view_pixels or n * hw > limits.max_scene_pixels:
            raise SceneError(f"{p}: {n} views of {hw} pixels is over the limits")
    elif arr.dtype not in (np.uint8, np.uint16):
        raise SceneError(f"{p}: views must be uint8 or uint16, got {arr.dtype}")
    lf = from_array(arr, grid if arr.ndim != 5 else None, meta={"reader": "npy", "input_paths": [str(p.resolve())]})
    return lf


def read_scene(path: str | os.PathLike, *, split: str = "train", baseline: float | None = None,
               focal: float | None = None, allow_outside: bool = False, limits: Limits = DEFAULT,
               grid: tuple[int, int] | None = None, progress=None, lazy: bool = False) -> LightField:
    """Read a light field from a folder (or a transforms JSON file), detecting its layout.

    Args:
        path: scene folder, ``transforms*.json`` file, or an ``.npy`` array of views
            (memory-mapped; ``grid`` gives its rows and columns).
        split: for NeRF-synthetic folders with ``transforms_<split>.json``; ``"all"`` reads every
            split as one posed capture (train, val, test, then others by name), recording the
            splits so that a decode writes them back as separate files.
        baseline, focal: override unknown grid geometry (scene units, pixels).
        allow_outside: read view files that lie outside the scene folder (off by default).
        limits: caps on the number of views and pixels, checked before pixels are read.
        grid: (rows, cols) for a plain folder of images (natural name order, row-major); a
            folder with its own layout file ignores it.
        progress: ``progress(stage, done, total)`` as views are decoded, or None.
        lazy: leave a grid's views in their image files, each decoded when a codec asks for it
            (``lf.views`` is then a :class:`formats.viewstack.ViewStack`): the ``tx`` encoder
            then holds no copy of the light field's pixels, at the cost of decoding most files
            twice (a 9×9 grid at 40 dB: 3.6× the raw input at peak instead of 4.2×; other
            codecs read every view first). Posed captures are read whole either way.

    Returns:
        the light field; ``meta["input_paths"]`` lists every file read (resolved).

    Raises:
        SceneError: not a folder, empty, no recognizable layout, unreadable/mismatched views,
            paths outside the scene, or sizes over the limits.
    """
    opts = ReadOptions(limits, allow_outside, progress, lazy)
    if split not in ("train", "val", "test") and not (isinstance(split, str) and split.isidentifier()):
        raise SceneError(f"split must be a plain name like train or test, got {split!r}")
    p = Path(path)
    if p.is_file() and p.suffix.lower() == ".json":
        return read_transforms(p, opts)
    if p.is_file() and p.suffix.lower() == ".npy":
        return read_npy(p, grid, limits)
    if not p.exists():
        raise SceneError(f"{p}: no such scene folder")
    if not p.is_dir():
        raise SceneError(f"{p}: a scene is a folder of views (or a transforms.json), not a single file")
    if (p / "scene.json").is_file():
        return read_grid(p, baseline=baseline, focal=focal, opts=opts)
    if (p / "poses_bounds.npy").is_file():
        return read_llff(p, opts)
    if split == "all" and not (p / "transforms.json").is_file() and any(p.glob("transforms_*.json")):
        return read_transform_splits(p, opts)
    for name in ("transforms.json", f"transforms_{split}.json"):
        if (p / name).is_file():
            lf = read_transforms(p / name, opts)
            others = sorted(q.name[len("transforms_"):-len(".json")] for q in p.glob("transforms_*.json")
                            if q.name != name and q.is_file())
            if others:      # splits not read: the CLI says so (a user may want them too)
                lf.meta["other_splits"] = others
            return lf
    splits = sorted(q.name[len("transforms_"):-len(".json")] for q in p.glob("transforms_*.json") if q.is_file())
    if splits:
        raise SceneError(f"{p}: no transforms_{split}.json (the splits here: {', '.join(splits)}; or --split all)")
    entries = [e for e in p.iterdir() if not e.name.startswith(".")]
    if not entries:
        raise SceneError(f"{p}: empty folder")
    if any(HCI_RE.match(e.name) for e in entries):
        return read_hci(p, baseline=baseline, focal=focal, opts=opts)
    if any(STANFORD_RE.match(e.name) for e in entries):
        return read_stanford(p, baseline=baseline, focal=focal, opts=opts)
    images = [e for e in entries if is_image(e)]
    if grid is not None:
        return read_image_folder(p, grid, baseline=baseline, focal=focal, opts=opts)
    raise SceneError(f"{p}: no recognizable light-field layout (expected scene.json, poses_bounds.npy, "
                     f"transforms.json, input_CamNNN.png or out_RR_CC_*.png; found {len(images)} image files "
                     f"among {len(entries)} entries; a plain folder of images needs --grid ROWSxCOLS)")


def view_filename(row: int, col: int, ext: str = ".png") -> str:
    """File name of a decoded view: ``rRR_cCC.png``."""
    return f"r{row:02d}_c{col:02d}{ext}"


def write_views(folder: str | os.PathLike, views: np.ndarray, *, rows: list[int] | None = None,
                cols: list[int] | None = None, ext: str = ".png", filename=None) -> list[Path]:
    """Write (R, C, H, W, Ch) views as ``rRR_cCC.png`` (16-bit PNG for uint16), atomically each,
    on a few threads; returns their paths in row-major order.

    ``rows``/``cols`` give the grid indices of the given views when they are a subset;
    ``filename(row, col)`` names the files instead (relative to ``folder``; subfolders are
    made, and a name that would leave ``folder`` is a FormatError).
    """
    from concurrent.futures import ThreadPoolExecutor

    from ..parallel import LOCAL_THREADS

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    rows = rows if rows is not None else list(range(views.shape[0]))
    cols = cols if cols is not None else list(range(views.shape[1]))
    jobs = []
    for i, r in enumerate(rows):
        for j, c in enumerate(cols):
            if filename is None:
                path = folder / view_filename(r, c, ext)
            else:
                from ..viewnames import output_path

                path = output_path(folder, filename(r, c))
                path.parent.mkdir(parents=True, exist_ok=True)
            jobs.append((path, views[i, j]))
    if len(jobs) == 1:
        write_image(*jobs[0])
    else:                                    # (image encoders release the GIL: files on a few threads)
        with ThreadPoolExecutor(LOCAL_THREADS) as pool:
            list(pool.map(lambda job: write_image(*job), jobs))
    return [path for path, _ in jobs]
