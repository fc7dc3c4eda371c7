"""Checks shared by the ``lfcodec`` commands: parsed option values and output paths (one
:class:`formats.errors.ParameterError` each, which the command line prints as one line)."""
from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from .errors import ParameterError
from .imageio import check_parent_folder


def ints(text: str, n: int, what: str) -> tuple[int, ...]:
    try:
        vals = tuple(int(x) for x in text.split(","))
    except ValueError:
        vals = ()
    if len(vals) != n or any(v < 0 for v in vals):
        raise ParameterError(f"{what} must be {n} non-negative integers separated by commas, got {text!r}")
    return vals


def refuse_input_overwrite(scene: Path, out: Path) -> None:
    so, o = scene.resolve(), out.resolve()
    if o == so or (so.is_dir() and so in o.parents and o.exists()):
        raise ParameterError(f"{out}: refusing to write over a file of the input scene {scene}")


def check_out_file(out: Path) -> None:
    """An output file's name: its folder exists and it is not itself a folder."""
    if out.is_dir():
        raise ParameterError(f"{out}: is a folder; give the output file's name")
    check_parent_folder(out)


def refuse_output_over_input(inp: str, out: Path) -> None:
    """An output that is the input file itself (under its own name, or another one: a link)."""
    if "://" in str(inp) or not Path(inp).is_file():
        return
    if out.resolve() == Path(inp).resolve() or (out.exists() and os.path.samefile(out, inp)):
        raise ParameterError(f"{out}: refusing to write over the input file {inp}")


def save_npy(path: Path, arr: np.ndarray) -> None:
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}.npy")
    try:
        np.save(tmp, arr, allow_pickle=False)
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def floats(text: str, n: int, what: str) -> tuple:
    try:
        vals = tuple(float(x) for x in text.split(","))
    except ValueError:
        vals = ()
    if len(vals) != n or not all(np.isfinite(vals)):
        raise ParameterError(f"{what} must be {n} comma-separated numbers, got {text!r}")
    return vals


def grid(text: str) -> tuple[int, int]:
    m = re.fullmatch(r"\s*(\d{1,5})\s*[xX]\s*(\d{1,5})\s*", text)
    if not m or int(m.group(1)) < 1 or int(m.group(2)) < 1:
        raise ParameterError(f"expected ROWSxCOLS (COLSxROWS for --quilt) with integers in 1..99999, e.g. "
                             f"9x9; got {text!r}")
    return int(m.group(1)), int(m.group(2))


def is_set(source) -> bool:
    """Whether ``source`` names a set of files a codec opens as one (an LFN tile set's manifest)."""
    from .registry import set_codec

    return set_codec(source) is not None


#: what ``decode --view ROW,COL --out FILE`` writes: formats that keep every channel and bit depth
#: (a JPEG, say, would turn a 16-bit grey + alpha view into 8-bit colour without a word)
VIEW_SUFFIXES = (".png", ".tif", ".tiff", ".npy")
#: names that stand for one file, not a folder, as decode's OUTDIR with --view or --block
FILE_SUFFIXES = VIEW_SUFFIXES + (".exr", ".jpg", ".jpeg", ".bmp", ".webp", ".gif", ".jp2", ".j2k", ".jxl", ".ppm")
