"""LFN configuration: one frozen dataclass, stored in the file's header."""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

from formats.errors import ParameterError

CODEC_ID = "lfn"
CODEC_VERSION = 3          # 3: steps in one section, cameras in meta.more; 2: sizes named *_neurons (1: *_width)
#: metadata a renderer of the first bytes does not need, stored after the network (meta.more)
MOVED_KEYS = ("scene.c2w", "scene.positions", "scene.names_z", "config.train")

#: on-wire keys of codec version 1 (files written before the network's width was renamed)
V1_KEYS = {"min_width": "min_neurons", "max_width": "max_neurons", "occupancy_width": "occupancy_neurons"}


@dataclass(frozen=True)
class LfnConfig:
    """A light field network with nested widths (continuous levels of detail).

    "Neurons" is the hidden width of the network (units per hidden layer); "width" is kept for
    images (pixels), as everywhere in lfcodec.

    Attributes:
        depth: hidden layers (Linear → LayerNorm → ReLU each).
        min_neurons: neurons of the base network (↔ 1/8 image scale).
        max_neurons: neurons of the full network (↔ 1/1 scale). Every count in between, and
            every fractional count, is a level of detail.
        occupancy_neurons: hidden neurons of the occupancy net (0 = none).
        in_features: 6 (Plücker coordinates: direction, moment).
        out_features: 4 (RGBA, colour premultiplied by alpha).
        min_scale: image scale of the base network (1/8).
    """

    depth: int = 6
    min_neurons: int = 16
    max_neurons: int = 128
    occupancy_neurons: int = 32
    in_features: int = 6
    out_features: int = 4
    min_scale: float = 0.125

    def __post_init__(self):
        for k in ("depth", "min_neurons", "max_neurons", "occupancy_neurons", "in_features", "out_features"):
            v = getattr(self, k)
            if isinstance(v, bool) or not isinstance(v, int):
                raise ParameterError(f"network {k} must be an integer, got {v!r}")
        if not (1 <= self.depth <= 32):
            raise ParameterError(f"depth must be 1..32, got {self.depth}")
        if not (1 <= self.min_neurons <= self.max_neurons <= 4096):
            raise ParameterError(f"need 1 <= min_neurons <= max_neurons <= 4096, got {self.min_neurons}, "
                                 f"{self.max_neurons}")
        if not 0 <= self.occupancy_neurons <= 4096:
            raise ParameterError(f"occupancy_neurons must be 0..4096, got {self.occupancy_neurons}")
        if (self.in_features, self.out_features) != (6, 4):
            raise ParameterError(f"networks map 6 Plücker features to 4 outputs, got {self.in_features}->"
                                 f"{self.out_features}")
        if not (isinstance(self.min_scale, (int, float)) and 0 < self.min_scale <= 1):
            raise ParameterError(f"min_scale must be in (0, 1], got {self.min_scale}")

    @staticmethod
    def from_dict(d: dict, version: int = 2) -> "LfnConfig":
        """From a file's ``config.network`` (version-1 keys are renamed)."""
        if not isinstance(d, dict):
            raise ParameterError("network config must be a JSON object")
        if version < 2:                          # version 1 names; either name is read (FORMAT.md)
            twice = [k for k, new in V1_KEYS.items() if k in d and new in d]
            if twice:
                raise ParameterError(f"network config names a size twice: {twice[0]} and {V1_KEYS[twice[0]]}")
            d = {V1_KEYS.get(k, k): v for k, v in d.items()}
        known = set(LfnConfig.__dataclass_fields__)
        if set(d) - known:
            raise ParameterError(f"unknown network config keys: {', '.join(sorted(set(d) - known))}")
        missing = {"depth", "min_neurons", "max_neurons", "occupancy_neurons"} - set(d)
        if missing:                              # a file states its network's sizes (FORMAT.md)
            raise ParameterError(f"network config lacks {', '.join(sorted(missing))}")
        return LfnConfig(**d)

    def scale_of(self, neurons: float) -> float:
        """Image scale a (fractional) neuron count stands for: log-linear from min_scale to 1."""
        if self.max_neurons == self.min_neurons:
            return 1.0
        t = min(max((neurons - self.min_neurons) / (self.max_neurons - self.min_neurons), 0.0), 1.0)
        return math.exp(math.log(self.min_scale) * (1.0 - t))

    def neurons_of(self, scale: float) -> float:
        """Inverse of :meth:`scale_of` (clamped to [min_neurons, max_neurons])."""
        if self.max_neurons == self.min_neurons or scale >= 1:
            return float(self.max_neurons)
        t = 1.0 - math.log(max(scale, self.min_scale)) / math.log(self.min_scale)
        return self.min_neurons + t * (self.max_neurons - self.min_neurons)

    def to_dict(self) -> dict:
        return asdict(self)
