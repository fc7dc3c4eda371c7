"""Original file names of a light field's views: recorded at encode, validated as untrusted
input at decode, and used (as PNG) for the decoded views, so a decoded folder keeps its names.

A name is a relative POSIX path from the scene's folder (``input_Cam012.png``,
``images/IMG_4021.JPG``, ``train/r_7.png``). A file's names are checked before any is used:
1..4 path components, each 1..128 characters, none ``.``/``..``, no leading ``/`` or ``~``, no
backslash, colon or control character, at most 200 characters in all, unique (ignoring case)
once the extension becomes ``.png``. Files whose names fail are FormatErrors at open; decoders
then also confine every output path to the output folder.

In a file's scene metadata the names are one string, ``names_z``: base64 of the zlib-deflated
JSON list (sequential names such as ``input_Cam000.png``… shrink to a few bytes per view);
inflating is bounded by what ``count`` names may take.
"""
from __future__ import annotations

import base64
import binascii
import json
import os
import zlib
from pathlib import Path, PurePosixPath

from .errors import FormatError

MAX_NAME = 200
MAX_PART = 128
MAX_PARTS = 4
_BAD = set('\\:\x7f') | {chr(i) for i in range(32)}


def relative_names(paths, root: Path) -> list[str] | None:
    """Relative POSIX names of view files under ``root`` (None when one is outside it or a
    name would not pass :func:`check_names`)."""
    out = []
    root = Path(root).resolve()
    for p in paths:
        try:
            rel = Path(os.path.abspath(p)).relative_to(root)
        except ValueError:
            return None
        out.append(PurePosixPath(*rel.parts).as_posix())
    try:
        check_names(out, len(out), "scene")
    except FormatError:
        return None
    return out


def png_name(name: str) -> str:
    """The decoded view's file name: the original with a ``.png`` extension."""
    p = PurePosixPath(name)
    return p.with_suffix(".png").as_posix() if p.suffix else p.as_posix() + ".png"


def check_names(names, count: int, where: str) -> list[str]:
    """Validate ``count`` view names from a file (see the module doc).

    Raises:
        FormatError: naming ``where`` and the first bad name.
    """
    if not isinstance(names, list) or len(names) != count:
        raise FormatError(f"{where}: names must be a list of {count} strings")
    seen = set()
    for n in names:
        if not isinstance(n, str) or not 1 <= len(n) <= MAX_NAME:
            raise FormatError(f"{where}: a view name must be a string of 1..{MAX_NAME} characters")
        parts = n.split("/")
        if n.startswith(("/", "~")) or not 1 <= len(parts) <= MAX_PARTS or _BAD & set(n) or any(
                p in ("", ".", "..") or len(p) > MAX_PART for p in parts):
            raise FormatError(f"{where}: unsafe view name {n[:80]!r}")
        key = png_name(n).lower()
        if key in seen:
            raise FormatError(f"{where}: two views are named {n[:80]!r} (as PNG, ignoring case)")
        seen.add(key)
    return list(names)


def output_path(folder: Path, name: str) -> Path:
    """``folder / png_name(name)``, refusing a path that resolves outside ``folder`` (a symlink
    inside the output folder, for instance)."""
    folder = Path(folder)
    p = folder / png_name(name)
    base = folder.resolve()
    if not Path(os.path.abspath(p.parent.resolve() / p.name)).is_relative_to(base):
        raise FormatError(f"{name!r}: the decoded view would be written outside {folder}")
    return p


def pack_names(names: list[str]) -> str:
    """The ``names_z`` string of a list of names."""
    return base64.b64encode(zlib.compress(json.dumps(names, separators=(",", ":")).encode(), 9)).decode("ascii")


def unpack_names(text, count: int, where: str) -> list[str]:
    """Names from a ``names_z`` string, validated (:func:`check_names`).

    Raises:
        FormatError: not base64/zlib/JSON, inflating past the bound, or bad names.
    """
    bound = count * (MAX_NAME * 6 + 8) + 16             # JSON of count names at most (escapes included)
    if not isinstance(text, str) or len(text) > 4 * bound:
        raise FormatError(f"{where}: names_z must be a string of at most {4 * bound} characters")
    try:
        raw = base64.b64decode(text.encode("ascii"), validate=True)
        z = zlib.decompressobj()
        data = z.decompress(raw, bound + 1)
        if len(data) > bound or not z.eof:
            raise FormatError(f"{where}: names_z inflates past {bound} bytes or is truncated")
        names = json.loads(data.decode("utf-8"))
    except (UnicodeError, binascii.Error, zlib.error, ValueError, RecursionError) as e:
        raise FormatError(f"{where}: names_z is not base64 of deflated JSON ({type(e).__name__})") from None
    return check_names(names, count, where)
