"""The normalized light field every scene reader returns and every codec consumes."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .errors import SceneError


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
        if v.ndim != 5:
            raise SceneError(f"views must be (rows, cols, H, W, C), got shape {v.shape}")
        if v.shape[4] not in (1, 2, 3, 4):
            raise SceneError(f"views must have 1-4 channels, got {v.shape[4]}")
        if v.dtype not in (np.uint8, np.uint16, np.float32):
            raise SceneError(f"views must be uint8, uint16 or float32, got {v.dtype}")
        if min(v.shape) == 0:
            raise SceneError(f"light field is empty: shape {v.shape}")
        self.positions = np.asarray(self.positions, dtype=np.float64).reshape(v.shape[0], v.shape[1], 3)
        if self.principal is None:
            self.principal = (v.shape[3] / 2.0, v.shape[2] / 2.0)

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
        return g

    @staticmethod
    def from_geometry(views: np.ndarray, g: dict, meta: dict | None = None) -> "LightField":
        """Rebuild a light field from decoded views and :meth:`geometry` output."""
        c2w = np.asarray(g["c2w"], dtype=np.float64) if "c2w" in g else None
        if "positions" in g:
            pos = np.asarray(g["positions"], dtype=np.float64)
        else:
            pos = grid_positions(views.shape[0], views.shape[1], tuple(g["baseline"]))
        return LightField(views=views, positions=pos, c2w=c2w,
                          focal=tuple(g["focal"]), principal=tuple(g["principal"]),
                          layout=g.get("layout", "grid"), meta=meta or {})


def _grid_baseline(positions: np.ndarray) -> list[float] | None:
    """[bx, by] when ``positions`` are exactly grid_positions(rows, cols, (bx, by)), else None."""
    r, c = positions.shape[:2]
    bx = float(positions[0, 1, 0] - positions[0, 0, 0]) if c > 1 else 1.0
    by = float(positions[0, 0, 1] - positions[1, 0, 1]) if r > 1 else 1.0
    if not (np.isfinite(bx) and np.isfinite(by)):
        return None
    return [bx, by] if np.array_equal(grid_positions(r, c, (bx, by)), positions) else None


def grid_positions(rows: int, cols: int, baseline: tuple[float, float] = (1.0, 1.0)) -> np.ndarray:
    """(rows, cols, 3) camera centres of a planar grid: x grows with col, y down with row."""
    r, c = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
    return np.stack([c * baseline[0], -r * baseline[1], np.zeros_like(r, dtype=float)], axis=-1).astype(np.float64)
