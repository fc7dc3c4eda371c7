"""Camera paths for rendered sequences: preset orbits and sweeps, or a file of cameras.

A camera is (s, t, focus, aperture): the grid position in view units (as ``--at``), the focus
disparity in pixels per view step (NaN = the file's disparity maps) and the synthetic-aperture
radius in view steps (0 = a pinhole view). A path is an (N, 4) float64 array.

Path specs (``lfcodec render --path SPEC``):
    ``orbit[:N]``   an ellipse around the grid centre, 80% of the way to the outer views (N frames,
                    default 60), a pinhole camera on the file's geometry;
    ``sweep[:N]``   along the middle row from the first column to the last and back;
    FILE            a text file with one camera per line, ``s,t[,focus[,aperture]]`` (``#``
                    comments and blank lines ignored; an empty focus field = the file's maps), or
                    a JSON list of such lists.

A light field network renders any camera pose: :func:`read_pose` reads one 4×4 camera-to-world
matrix from a file, and :func:`quilt_positions` / :func:`assemble_quilt` lay out the views of a
quilt for light-field displays whatever renders them.
"""
from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np

from formats.errors import ParameterError

MAX_FRAMES = 100_000
MAX_PATH_FILE = 16 << 20
MAX_POSE_FILE = 1 << 20
DEFAULT_FRAMES = 60
MAX_QUILT = 256


def orbit(rows: int, cols: int, frames: int = DEFAULT_FRAMES, radius: float = 0.8) -> np.ndarray:
    """(frames, 4) cameras on an ellipse around the grid centre (``radius`` of the way to the
    outer views), starting at the top and turning clockwise; a closed loop (the last frame is
    one step before the first)."""
    _check_frames(frames)
    a = 2 * np.pi * np.arange(frames) / frames
    s = (rows - 1) / 2 * (1 - radius * np.cos(a))
    t = (cols - 1) / 2 * (1 + radius * np.sin(a))
    return np.stack([s, t, np.full(frames, np.nan), np.zeros(frames)], axis=1)


def sweep(rows: int, cols: int, frames: int = DEFAULT_FRAMES) -> np.ndarray:
    """(frames, 4) cameras along the middle row, first column to last and back."""
    _check_frames(frames)
    u = np.arange(frames) / max(1, frames - 1)
    t = (cols - 1) * (1 - np.abs(2 * u - 1))
    return np.stack([np.full(frames, (rows - 1) / 2), t, np.full(frames, np.nan), np.zeros(frames)], axis=1)


def read_path(spec: str, rows: int, cols: int) -> np.ndarray:
    """The (N, 4) cameras of a path spec (see the module doc).

    Raises:
        ParameterError: an unknown preset, a bad frame count, a file that cannot be read or
            parsed, a non-finite position or a negative aperture.
    """
    m = re.fullmatch(r"\s*(orbit|sweep)(?::(\d{1,7}))?\s*", spec or "")
    if m:
        n = int(m.group(2)) if m.group(2) else DEFAULT_FRAMES
        return (orbit if m.group(1) == "orbit" else sweep)(rows, cols, n)
    p = Path(spec)
    if not spec or not p.is_file():
        raise ParameterError(f"--path {spec!r}: not a preset (orbit[:N], sweep[:N]) nor a file of cameras")
    text = _read_text(p, MAX_PATH_FILE, "camera path")
    rows_ = _parse_json(text, p) if text.lstrip().startswith("[") else _parse_lines(text, p)
    if not rows_:
        raise ParameterError(f"{p}: no cameras in the path file")
    _check_frames(len(rows_))
    cams = np.array(rows_, dtype=np.float64)
    if not np.isfinite(cams[:, :2]).all() or not np.isfinite(cams[:, 3]).all() or (cams[:, 3] < 0).any() \
            or np.isinf(cams[:, 2]).any():
        raise ParameterError(f"{p}: positions must be finite, focus finite or empty, aperture finite and >= 0")
    return cams


def _read_text(p: Path, limit: int, what: str) -> str:
    """A UTF-8 text file of at most ``limit`` bytes (ParameterError otherwise)."""
    if p.stat().st_size > limit:
        raise ParameterError(f"{p}: a {what} file is at most {limit >> 20} MiB")
    try:
        return p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise ParameterError(f"{p}: cannot read the {what} ({e})") from None


def _check_frames(n) -> None:
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or not 1 <= n <= MAX_FRAMES:
        raise ParameterError(f"a camera path has 1..{MAX_FRAMES} frames, got {n!r}")


def _camera(vals: list, where: str) -> list:
    if not 2 <= len(vals) <= 4:
        raise ParameterError(f"{where}: a camera is s,t[,focus[,aperture]], got {len(vals)} values")
    out = []
    for v in vals:
        if v is None or (isinstance(v, str) and not v.strip()):
            out.append(math.nan)
            continue
        if isinstance(v, bool):
            raise ParameterError(f"{where}: {v!r} is not a number")
        try:
            out.append(float(v))
        except (TypeError, ValueError):
            raise ParameterError(f"{where}: {v!r} is not a number") from None
    out += [math.nan, 0.0][len(out) - 2:]
    if math.isnan(out[0]) or math.isnan(out[1]) or math.isnan(out[3]):
        raise ParameterError(f"{where}: s, t and aperture must be numbers")
    return out


def _parse_lines(text: str, p: Path) -> list:
    cams = []
    for i, line in enumerate(text.splitlines(), 1):
        line = line.split("#", 1)[0].strip()
        if line:
            cams.append(_camera(line.split(","), f"{p}:{i}"))
            if len(cams) > MAX_FRAMES:
                _check_frames(len(cams))
    return cams


def _parse_json(text: str, p: Path) -> list:
    try:
        data = json.loads(text)
    except (ValueError, RecursionError) as e:
        raise ParameterError(f"{p}: not valid JSON ({e})") from None
    if not isinstance(data, list) or not all(isinstance(c, list) for c in data):
        raise ParameterError(f"{p}: a JSON camera path is a list of [s, t, focus, aperture] lists")
    _check_frames(len(data)) if data else None
    return [_camera(c, f"{p}[{i}]") for i, c in enumerate(data)]


def read_pose(spec: str) -> np.ndarray:
    """One camera-to-world matrix (OpenGL axes: x right, y up, looking down −z; scene units) from
    a file: a JSON 4×4 list of lists (or a ``{"transform_matrix": ...}`` frame of a
    transforms.json), or 16 numbers in row-major order separated by spaces, commas or newlines.

    Returns:
        (4, 4) float64 array (finite; the renderer checks that it is a usable camera).

    Raises:
        ParameterError: a missing or over-large file, or one that does not hold 16 finite numbers.
    """
    p = Path(spec)
    if not p.is_file():
        raise ParameterError(f"--pose {spec!r}: no such file (a 4x4 camera-to-world matrix, JSON or 16 numbers)")
    text = _read_text(p, MAX_POSE_FILE, "pose")
    if text.lstrip().startswith(("[", "{")):
        try:
            data = json.loads(text)
        except (ValueError, RecursionError) as e:
            raise ParameterError(f"{p}: not valid JSON ({e})") from None
        if isinstance(data, dict):
            data = data.get("transform_matrix")
        ok = isinstance(data, list) and len(data) == 4 and all(isinstance(r, list) and len(r) == 4 for r in data) \
            and all(isinstance(v, (int, float)) and not isinstance(v, bool) for r in data for v in r)
        vals = [float(v) for r in data for v in r] if ok else []
    else:
        try:
            vals = [float(v) for v in re.split(r"[\s,]+", text.strip()) if v]
        except ValueError:
            vals = []
    if len(vals) != 16 or not all(math.isfinite(v) for v in vals):
        raise ParameterError(f"{p}: a pose is a 4x4 camera-to-world matrix of 16 finite numbers")
    return np.array(vals, np.float64).reshape(4, 4)


def turn_frames(spec: str) -> int | None:
    """Frames of a ``turn[:N]`` path spec (a free camera turned a full circle about the scene,
    which light field networks render; default 60 frames), or None for any other spec."""
    m = re.fullmatch(r"\s*turn(?::(\d{1,7}))?\s*", spec or "")
    if not m:
        return None
    n = int(m.group(1)) if m.group(1) else DEFAULT_FRAMES
    _check_frames(n)
    return n


def quilt_views(qcols: int, qrows: int) -> int:
    """Views of a qcols × qrows quilt, checked to be 1..MAX_QUILT."""
    n = qrows * qcols
    if isinstance(n, bool) or not 1 <= n <= MAX_QUILT:
        raise ParameterError(f"a quilt has 1..{MAX_QUILT} views")
    return n


def quilt_positions(rows: int, cols: int, qcols: int, qrows: int) -> np.ndarray:
    """(qcols·qrows, 2) grid positions (s, t) of a quilt's views: along the grid's middle row from
    the first column to the last (the centre alone for a one-view quilt)."""
    n = quilt_views(qcols, qrows)
    ts = np.linspace(0, cols - 1, n) if n > 1 else np.array([(cols - 1) / 2])
    return np.stack([np.full(n, (rows - 1) / 2), ts], axis=1)


def assemble_quilt(views: list, qcols: int, qrows: int) -> np.ndarray:
    """One (qrows·H, qcols·W, C) image of ``qcols·qrows`` equal-sized (H, W, C) views, left to
    right from the bottom-left (as Looking Glass quilts are laid out)."""
    h, w = views[0].shape[:2]
    out = np.zeros((qrows * h, qcols * w) + views[0].shape[2:], views[0].dtype)
    for i, v in enumerate(views):
        qr, qc = qrows - 1 - i // qcols, i % qcols
        out[qr * h:(qr + 1) * h, qc * w:(qc + 1) * w] = v
    return out
