"""RLFC parameters: one frozen dataclass, stored in the file's header."""
from __future__ import annotations

from dataclasses import asdict, dataclass

from formats.codec_api import check_field_types
from formats.errors import ParameterError

PROFILES = ("bise", "dcp")


#: command-line flags whose names are not their parameter's (``--`` + the name with dashes otherwise)
FLAGS = {"weighted": "weighted-prediction", "disp_frac_bits": "disparity-bits"}


def flags(names) -> str:
    """``--flag, --flag`` of parameter names, as the command line spells them (error messages)."""
    return ", ".join("--" + FLAGS.get(k, k.replace("_", "-")) for k in names)


@dataclass(frozen=True)
class RlfcParams:
    """Encoder parameters of the RLFC codec.

    Attributes:
        tree_height: levels of Representative Key Views above the views (capped where a level
            would have a single node).
        block_size: B, residual block edge in pixels (blocks are B×B×planes).
        threshold: pixel threshold T: residual values with |r| <= T (pixel units) become 0.
        quant: quantization step Q (pixel units of the input depth, >= 1, resolution 1/16);
            1 = lossless. The CLI's default is 8 for 8-bit input and 8·65535/255 for 16-bit.
        energy: block-energy threshold E: a block whose weighted mean squared dequantized
            residual is below E (pixel units²) is not stored.
        sigma: Gaussian filter width, in units of a level's view spacing.
        top_codec: "auto" (smaller of lossless JPEG 2000 and JPEG XL), "j2k" or "jxl".
        top_psnr: None = lossless top level; a number = lossy JPEG 2000 at that PSNR (dB),
            whose decoded pixels feed the closed loop.
        profile: "bise" (the paper's: Gaussian key-view tree, every significant block
            BISE-packed) or "dcp" (disparity-compensated prediction from 3×3-cluster key views,
            residual blocks BISE-packed; grids only).
        max_disparity: dcp: largest |disparity| searched, pixels per view step (the search starts
            at ±4 and widens only where blocks need it).
        disp_frac_bits: dcp: disparity precision, 1/2^F pixel per view step (0 = whole pixels;
            3 = 1/8 px, bilinear sub-pixel prediction).
        disp_smooth: dcp: the disparity map takes its 3×3 median wherever that costs less than
            this fraction more prediction error (0 = off); a smoother map compresses better.
    """

    tree_height: int = 3
    block_size: int = 8
    threshold: float = 0.0
    quant: float = 1.0
    energy: float = 0.0
    sigma: float = 1.0
    top_codec: str = "auto"
    top_psnr: float | None = None
    profile: str = "bise"
    max_disparity: int = 32
    disp_frac_bits: int = 3
    disp_smooth: float = 0.1

    def __post_init__(self) -> None:
        check_field_types(self)           # types first: a string or a list fails range tests untyped
        if not 0 <= int(self.tree_height) <= 16 or int(self.tree_height) != self.tree_height:
            raise ParameterError(f"tree height must be an integer 0..16, got {self.tree_height}")
        if self.block_size not in (2, 4, 8, 16, 32):
            raise ParameterError(f"block size must be 2, 4, 8, 16 or 32, got {self.block_size}")
        if not self.threshold >= 0:
            raise ParameterError(f"threshold must be >= 0, got {self.threshold}")
        if not 1 <= self.quant <= 131072:
            raise ParameterError(f"quant step must be within 1..131072, got {self.quant}")
        if not self.energy >= 0:
            raise ParameterError(f"energy threshold must be >= 0, got {self.energy}")
        if not self.sigma > 0:
            raise ParameterError(f"sigma must be > 0, got {self.sigma}")
        if self.top_codec not in ("auto", "j2k", "jxl"):
            raise ParameterError(f"top codec must be auto, j2k or jxl, got {self.top_codec!r}")
        if self.top_psnr is not None and not 10 <= self.top_psnr <= 120:
            raise ParameterError(f"top-level PSNR must be within 10..120 dB, got {self.top_psnr}")
        if not 0 <= int(self.max_disparity) <= 64:
            raise ParameterError(f"max disparity must be 0..64, got {self.max_disparity}")
        if not 0 <= int(self.disp_frac_bits) <= 4 or int(self.disp_frac_bits) != self.disp_frac_bits:
            raise ParameterError(f"disparity precision must be 0..4 fractional bits, got {self.disp_frac_bits}")
        if not 0 <= self.disp_smooth <= 10:
            raise ParameterError(f"disparity smoothing tolerance must be within 0..10, got {self.disp_smooth}")
        if self.profile not in PROFILES:
            raise ParameterError(f"unknown profile {self.profile!r} (available: {', '.join(PROFILES)})")

    @property
    def q16(self) -> int:
        """Quantization step in 1/16 pixel units (16 = lossless)."""
        return max(16, int(round(self.quant * 16)))

    def to_dict(self) -> dict:
        return asdict(self)
