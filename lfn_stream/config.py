"""LFN configuration: one frozen dataclass, stored in the file's header."""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

from formats.errors import ParameterError


@dataclass(frozen=True)
class LfnConfig:
    """A light field network with nested widths (continuous levels of detail).

    Attributes:
        depth: hidden layers (Linear → LayerNorm → ReLU each).
        min_width: width of the base network (level min_width ↔ 1/8 image scale).
        max_width: full width (↔ 1/1 scale). Every width in between is a level.
        occupancy_width: hidden width of the occupancy net (0 = none).
        in_features: 6 (Plücker coordinates: direction, moment).
        out_features: 4 (RGBA, colour premultiplied by alpha).
        min_scale: image scale of the base network (1/8).
    """

    depth: int = 6
    min_width: int = 16
    max_width: int = 128
    occupancy_width: int = 32
    in_features: int = 6
    out_features: int = 4
    min_scale: float = 0.125

    def __post_init__(self):
        if not (1 <= self.depth <= 32):
            raise ParameterError(f"depth must be 1..32, got {self.depth}")
        if not (1 <= self.min_width <= self.max_width <= 4096):
            raise ParameterError(f"need 1 <= min_width <= max_width <= 4096, got {self.min_width}, {self.max_width}")
        if not (0 < self.min_scale <= 1):
            raise ParameterError(f"min_scale must be in (0, 1], got {self.min_scale}")

    def scale_of(self, width: float) -> float:
        """Image scale a (fractional) width stands for: log-linear from min_scale to 1."""
        if self.max_width == self.min_width:
            return 1.0
        t = min(max((width - self.min_width) / (self.max_width - self.min_width), 0.0), 1.0)
        return math.exp(math.log(self.min_scale) * (1.0 - t))

    def width_of(self, scale: float) -> float:
        """Inverse of :meth:`scale_of` (clamped to [min_width, max_width])."""
        if self.max_width == self.min_width or scale >= 1:
            return float(self.max_width)
        t = 1.0 - math.log(max(scale, self.min_scale)) / math.log(self.min_scale)
        return self.min_width + t * (self.max_width - self.min_width)

    def to_dict(self) -> dict:
        return asdict(self)
