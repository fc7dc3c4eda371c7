"""The RLFC header common to every profile: one typed, validated schema.

``RlfcHeader.read`` checks types, ranges and the products that drive allocations (views,
pixels, blocks) against :class:`formats.limits.Limits` before anything is allocated; the
profile then validates its own keys of the same config (``Fields``). The encoder writes the
same fields through :meth:`RlfcHeader.to_config`.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from formats.errors import FormatError
from formats.limits import DEFAULT, Limits
from formats.lightfield import read_geometry
from formats.schema import Fields

CODEC_ID = "rlfc"
CODEC_VERSION = 1
BLOCK_SIZES = (2, 4, 8, 16, 32, 64)


@dataclass(frozen=True)
class RlfcHeader:
    """Geometry of the coded planes.

    Attributes:
        profile: on-wire profile id. rows, cols: the view grid. height, width: a view in
            pixels. channels: 1..4; planes: P (= channels). dtype: uint8 or uint16.
        block_size: B. padded: (Hp, Wp), multiples of B ≥ (height, width). blocks: (nby, nbx).
    """

    profile: str
    rows: int
    cols: int
    height: int
    width: int
    channels: int
    planes: int
    dtype: np.dtype
    block_size: int
    padded: tuple[int, int]
    blocks: tuple[int, int]

    @property
    def n_views(self) -> int:
        return self.rows * self.cols

    def to_config(self) -> dict:
        """The header's own entries of a file's config."""
        return {"profile": self.profile, "block_size": self.block_size, "planes": self.planes,
                "channels": self.channels, "dtype": str(self.dtype), "height": self.height, "width": self.width,
                "padded": list(self.padded), "blocks": list(self.blocks)}

    @staticmethod
    def for_views(profile: str, rows: int, cols: int, shape: tuple, dtype, block_size: int) -> "RlfcHeader":
        """Header of views of ``shape`` (H, W, C) coded with blocks of ``block_size``."""
        h, w, c = shape
        hp, wp = -(-h // block_size) * block_size, -(-w // block_size) * block_size
        return RlfcHeader(profile, rows, cols, h, w, c, c, np.dtype(dtype), block_size, (hp, wp),
                          (hp // block_size, wp // block_size))

    @staticmethod
    def read(meta: dict, name: str, limits: Limits = DEFAULT) -> tuple["RlfcHeader", Fields]:
        """Validate a file's metadata → (header, config Fields for the profile).

        Raises:
            FormatError: a missing, mistyped or out-of-range field, or sizes over ``limits``.
        """
        m = Fields(meta, f"{name}: metadata")
        cfg = m.sub("config")
        scene = m.sub("scene")
        geo = read_geometry(scene.obj, f"{name}: scene", limits)
        rows, cols = geo["rows"], geo["cols"]
        profile = cfg.str("profile", max_len=32, default="bise")
        B = cfg.int("block_size", choices=BLOCK_SIZES)
        h = cfg.int("height", 1, limits.max_view_pixels)
        w = cfg.int("width", 1, limits.max_view_pixels)
        if h * w > limits.max_view_pixels:
            raise FormatError(f"{name}: views of {h}x{w} pixels exceed the limit of {limits.max_view_pixels} pixels")
        c = cfg.int("channels", 1, 4)
        cfg.int("planes", choices=(c,))
        dtype = np.dtype(cfg.str("dtype", choices=("uint8", "uint16")))
        hdr = RlfcHeader.for_views(profile, rows, cols, (h, w, c), dtype, B)
        if cfg.int_list("padded", length=2) != list(hdr.padded) or cfg.int_list("blocks", length=2) != list(hdr.blocks):
            raise FormatError(f"{name}: config padded/blocks do not match {h}x{w} pixels in blocks of {B}")
        for k, want in (("height", h), ("width", w), ("channels", c), ("dtype", str(dtype))):
            if scene.has(k) and scene.obj[k] != want:
                raise FormatError(f"{name}: scene {k} {scene.obj[k]!r} disagrees with the codec config ({want!r})")
        return hdr, cfg
