"""The normalized light field every scene reader returns and every codec consumes."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .errors import FormatError, SceneError
from .limits import DEFAULT, Limits
from .schema import Fields


@dataclass
class LightField:
    """A grid (or 1 × N sequence) of views of one scene, with cameras.

    Attributes:
        views: (R, C, H, W, Ch) uint8, uint16 or float32 pixels. Ch is 1 (grey), 2 (grey +
            alpha), 3 (RGB) or 4 (RGBA, straight alpha). Unordered captures are 1 × N.
        positions: (R, C, 3) float64 camera centres in scene units.
        c2w: (R, C, 4, 4) float64 camera-to-world matrices (OpenGL camera: x right, y up,
            looking down -z), or None when only positions are known (parallel grids).
        focal: (fx, fy) focal length in pixels.
        principal: (cx, cy) principal point in pixels (pixel centres at +0.5).
        layout: "grid" (regular plane of parallel cameras) or "posed" (irregular cameras).
        meta: JSON-able facts about the source (reader, file names, assumptions made).
    """

    views: np.ndarray
    positions: np.ndarray
    c2w: np.ndarray | None = None
    focal: tuple[float, float] = (1.0, 1.0)
    principal: tuple[float, float] | None = None
    layout: str = "grid"
    meta: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        v = self.views
        if not all(hasattr(v, k) for k in ("ndim", "shape", "dtype")):    # (numpy, or a lazy stack of views)
            raise SceneError(f"views must be an array (rows, cols, H, W, C), got {type(v).__name__}")
        if v.ndim != 5:
            raise SceneError(f"views must be (rows, cols, H, W, C), got shape {v.shape}")
        if v.shape[4] not in (1, 2, 3, 4):
            raise SceneError(f"views must have 1-4 channels, got {v.shape[4]}")
        if v.dtype not in (np.uint8, np.uint16, np.float32):
            raise SceneError(f"views must be uint8, uint16 or float32, got {v.dtype}")
        if min(v.shape) == 0:
            raise SceneError(f"light field is empty: shape {v.shape}")
        self.positions = _finite(self.positions, (v.shape[0], v.shape[1], 3), "positions")
        if self.c2w is not None:
            self.c2w = _finite(self.c2w, (v.shape[0], v.shape[1], 4, 4), "c2w")
        if self.layout not in ("grid", "posed"):
            raise SceneError(f"layout must be 'grid' or 'posed', got {self.layout!r}")
        fx, fy = _finite(self.focal, (2,), "focal")
        if not (fx > 0 and fy > 0):
            raise SceneError(f"focal lengths must be > 0 px, got {tuple(self.focal)}")
        if self.principal is None:
            self.principal = (v.shape[3] / 2.0, v.shape[2] / 2.0)
        _finite(self.principal, (2,), "principal")

    @property
    def rows(self) -> int:
        return self.views.shape[0]

    @property
    def cols(self) -> int:
        return self.views.shape[1]

    @property
    def height(self) -> int:
        return self.views.shape[2]

    @property
    def width(self) -> int:
        return self.views.shape[3]

    @property
    def channels(self) -> int:
        return self.views.shape[4]

    @property
    def has_alpha(self) -> bool:
        return self.channels in (2, 4)

    @property
    def peak(self) -> float:
        """Peak value for PSNR: 255, 65535 or 1.0 (float)."""
        return {np.dtype(np.uint8): 255.0, np.dtype(np.uint16): 65535.0}.get(self.views.dtype, 1.0)

    def geometry(self) -> dict:
        """JSON-able scene geometry for a file's metadata. A regular planar grid is written as
        its ``baseline`` [bx, by] (positions = :func:`grid_positions`), anything else as the
        list of ``positions``."""
        g = {
            "rows": self.rows, "cols": self.cols, "height": self.height, "width": self.width,
            "channels": self.channels, "dtype": str(self.views.dtype), "layout": self.layout,
            "focal": [float(self.focal[0]), float(self.focal[1])],
            "principal": [float(self.principal[0]), float(self.principal[1])],
        }
        base = _grid_baseline(self.positions)
        if base is not None and self.c2w is None:
            g["baseline"] = base
        else:
            g["positions"] = np.round(self.positions, 9).tolist()
        if self.c2w is not None:
            g["c2w"] = np.round(self.c2w, 9).tolist()
        names = self.meta.get("view_names")
        if isinstance(names, list) and len(names) == self.rows * self.cols:
            from .viewnames import pack_names

            g["names_z"] = pack_names(list(names))
        splits = self.meta.get("splits")
        if isinstance(splits, list) and sum(n for _, n in splits) == self.rows * self.cols:
            g["splits"] = [[str(k), int(n)] for k, n in splits]
        return g

    @staticmethod
    def from_geometry(views: np.ndarray, g: dict, meta: dict | None = None, limits: Limits = DEFAULT) -> "LightField":
        """Rebuild a light field from decoded views and :meth:`geometry` output (checked by
        :func:`read_geometry` under ``limits``)."""
        g = read_geometry(g, "scene", limits, rows=views.shape[0], cols=views.shape[1])
        c2w = g.get("c2w")
        if "positions" in g:
            pos = g["positions"]
        else:
            pos = grid_positions(views.shape[0], views.shape[1], tuple(g["baseline"]))
        return LightField(views=views, positions=pos, c2w=c2w,
                          focal=tuple(g["focal"]), principal=tuple(g["principal"]) if "principal" in g else None,
                          layout=g.get("layout", "grid"), meta=meta or {})


def _grid_baseline(positions: np.ndarray) -> list[float] | None:
    """[bx, by] when ``positions`` are exactly grid_positions(rows, cols, (bx, by)), else None."""
    r, c = positions.shape[:2]
    bx = float(positions[0, 1, 0] - positions[0, 0, 0]) if c > 1 else 1.0
    by = float(positions[0, 0, 1] - positions[1, 0, 1]) if r > 1 else 1.0
    if not (np.isfinite(bx) and np.isfinite(by)):
        return None
    return [bx, by] if np.array_equal(grid_positions(r, c, (bx, by)), positions) else None


def _finite(x, shape: tuple, what: str) -> np.ndarray:
    """``x`` as a float64 array of ``shape`` with finite values, else a SceneError."""
    try:
        a = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError):
        raise SceneError(f"{what} must be numbers, got {type(x).__name__}") from None
    if a.size != int(np.prod(shape)):
        raise SceneError(f"{what} must have shape {shape}, got {a.shape}")
    if not np.isfinite(a).all():
        raise SceneError(f"{what} must be finite")
    return a.reshape(shape)


def grid_positions(rows: int, cols: int, baseline: tuple[float, float] = (1.0, 1.0)) -> np.ndarray:
    """(rows, cols, 3) camera centres of a planar grid: x grows with col, y down with row."""
    r, c = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
    return np.stack([c * baseline[0], -r * baseline[1], np.zeros_like(r, dtype=float)], axis=-1).astype(np.float64)


def _finite_array(v, shape: tuple, where: str, key: str) -> np.ndarray:
    """A JSON list → float64 array of exactly ``shape`` with finite entries, else FormatError."""
    def has_bool(x, depth: int) -> bool:          # JSON true/false are not numbers (float() would take them)
        if isinstance(x, bool):
            return True
        return depth > 0 and isinstance(x, list) and any(has_bool(y, depth - 1) for y in x)

    try:
        if has_bool(v, len(shape)):
            raise TypeError
        a = np.asarray(v, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise FormatError(f"{where}: field {key!r} must be a {'x'.join(map(str, shape))} array of numbers") from None
    if a.shape != shape or not np.isfinite(a).all():
        raise FormatError(f"{where}: field {key!r} must be a {'x'.join(map(str, shape))} array of finite numbers, "
                          f"got shape {a.shape}")
    return a


def read_geometry(g: dict, where: str, limits: Limits = DEFAULT, rows: int | None = None,
                  cols: int | None = None) -> dict:
    """Validate a file's scene geometry (what :meth:`LightField.geometry` writes).

    Checks types, ranges and shapes — rows × cols against ``limits.max_views``, height ×
    width against ``limits.max_view_pixels``, finite focal/principal/baseline, positions
    (rows, cols, 3) and c2w (rows, cols, 4, 4) — before anything is built from it.

    Returns:
        a dict with rows, cols, height, width, channels, dtype, layout, focal, principal and
        either baseline (list) or positions ((rows, cols, 3) array), plus c2w and the views'
        original file names (``names``, from ``names_z``: :mod:`formats.viewnames`) and the
        splits of a posed capture (``splits``: [(name, views)] in view order) when present.

    Raises:
        FormatError naming ``where`` and the field.
    """
    f = Fields(g, where)
    out = {}
    out["rows"] = f.int("rows", 1, limits.max_views) if rows is None else rows
    out["cols"] = f.int("cols", 1, limits.max_views) if cols is None else cols
    if out["rows"] * out["cols"] > limits.max_views:
        raise FormatError(f"{where}: {out['rows']}x{out['cols']} views exceed the limit of {limits.max_views}")
    for k in ("height", "width"):
        if f.has(k) or rows is None:
            out[k] = f.int(k, 1, limits.max_view_pixels)
    if rows is None and out["height"] * out["width"] > limits.max_view_pixels:
        raise FormatError(f"{where}: views of {out['height']}x{out['width']} exceed the limit of "
                          f"{limits.max_view_pixels} pixels")
    if f.has("channels") or rows is None:
        out["channels"] = f.int("channels", 1, 4)
    if f.has("dtype") or rows is None:
        out["dtype"] = f.str("dtype", choices=("uint8", "uint16", "float32"))
    out["layout"] = f.str("layout", choices=("grid", "posed"), default="grid")
    out["focal"] = _finite_array(f._get("focal", [1.0, 1.0]), (2,), where, "focal").tolist()
    if f.has("principal"):
        out["principal"] = _finite_array(f.obj["principal"], (2,), where, "principal").tolist()
    shape = (out["rows"], out["cols"])
    if f.has("positions"):
        out["positions"] = _finite_array(f.obj["positions"], shape + (3,), where, "positions")
    else:
        out["baseline"] = _finite_array(f._get("baseline", [1.0, 1.0]), (2,), where, "baseline").tolist()
        steps = np.maximum([out["cols"] - 1, out["rows"] - 1], 1)
        if not (np.abs(out["baseline"]) < 1e100 / steps).all():       # the grid's extent (squared in distances)
            raise FormatError(f"{where}: field 'baseline' times the grid size overflows the camera positions")
    if f.has("c2w"):
        out["c2w"] = _finite_array(f.obj["c2w"], shape + (4, 4), where, "c2w")
    if f.has("splits"):
        sp = f.obj["splits"]
        n_views = out["rows"] * out["cols"]
        if not (isinstance(sp, list) and 1 <= len(sp) <= 64 and all(
                isinstance(x, list) and len(x) == 2 and isinstance(x[0], str) and x[0].isidentifier()
                and len(x[0]) <= 32 and isinstance(x[1], int) and not isinstance(x[1], bool) and x[1] >= 1
                for x in sp) and len({x[0] for x in sp}) == len(sp) and sum(x[1] for x in sp) == n_views):
            raise FormatError(f"{where}: field 'splits' must be a list of distinct [name, views] pairs (plain "
                              f"names, counts >= 1) covering the {n_views} views in order")
        out["splits"] = [(x[0], x[1]) for x in sp]
    if f.has("names_z"):
        from .viewnames import unpack_names

        out["names"] = unpack_names(f.obj["names_z"], out["rows"] * out["cols"], f"{where}: names_z")
    return out
