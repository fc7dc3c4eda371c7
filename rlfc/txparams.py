"""Parameters of the ``tx`` profile's encoder (:class:`TxParams`) and what a file records of them
(:func:`params_info`)."""
from __future__ import annotations

from dataclasses import asdict, dataclass

from formats.codec_api import check_field_types
from formats.errors import ParameterError

#: encoder decisions :attr:`TxParams.ablate` may turn off
ABLATE = ("intra_tbs", "j2k_all", "lambda_trim", "maps_reprice", "promote", "rdoq", "ref_modes")


@dataclass(frozen=True)
class TxParams:
    """Encoder parameters of the ``tx`` profile (stored in the file for information).

    Attributes:
        block_size: random-access block edge in pixels (a multiple of 8).
        key_spacing: views between key views along rows and columns (0 = chosen by grid size).
        key_ratio: key views' quantizer step is the others' divided by this (0 = chosen from
            how much the other views inherit from the keys: :meth:`TxEncoder.auto_key_ratio`).
        lam: λ = lam·Δ² (Δ the luma step of the views coded).
        max_disparity: largest |disparity| searched, pixels per view step.
        step: luma quantizer step Δ in pixel units (None: rate control or the default).
        lossless: every plane coded exactly (no transform).
        intra_codec: intra key views as "j2k" (JPEG 2000 at the quality the transform path
            reaches; views with alpha: their colour, the alpha plane exact after it), "tx"
            (thumbnail + transform), or "auto" (j2k when lossy).
        search_sample: a PSNR target's search codes the key views and every SEARCH_STRIDE-th
            other view (grids with at least SEARCH_MIN_VIEWS other views), then checks the
            chosen step on every view (False: every search pass codes every view).
        ablate: encoder decisions turned off, to measure what each buys (``tools/ablation_tx.py``;
            the decoder is the same): any of :data:`ABLATE` — "ref_modes" (every 8×8 block blends
            its references; no single-reference modes), "rdoq" (levels rounded to nearest, the
            last position is the last nonzero: no rate-distortion quantization), "intra_tbs" (no
            intra 8×8 blocks), "promote" (no view coded alone as a JPEG 2000 key), "lambda_trim"
            (no λ trim between two quantizer steps), "maps_reprice" (the maps' corrections are
            not judged again at the coding λ the probe predicts), "j2k_all" (a grid whose file
            codes most views alone does not try every view as JPEG 2000).
        key_split: streams per key-view block row (0 = chosen from the rows' estimated bytes:
            :meth:`TxEncoder.key_split`); more streams parse faster as parallel lanes and cost
            about 4 bytes each.
        weighted: weighted prediction (``tx`` version 4): each predicted view's prediction gets
            a gain and an offset per plane, fitted by least squares, where a plane's fit takes
            :data:`rlfc.txpredict.FIT_MIN_GAIN` of its prediction error away, error worth
            :data:`rlfc.txpredict.FIT_PRICE_BITS` bits at the view's λ, and lowers the view's
            estimated rate-distortion cost by more than its parameters' bits
            (:func:`rlfc.txpredict.priced_weights`: an occluder's blocks, coded either way, do not
            buy a fit that adds error to skipped blocks): views exposed differently
            (hci_antinous with a gain per view in [0.9, 1.1] at 40 dB, −79% bytes), vignetting,
            noisy predicted chroma. On by default; a file without a kept fit stays version 2/3
            (BENCHMARKS.md, weighted prediction).
        warps: per-view warps (``tx`` version 5, :mod:`rlfc.txwarp`) for rigs that are not
            rectified: each view's rotation, scale and shift against the grid is estimated from
            the views (:func:`formats.rectify.estimate_warps`, 2-8 CPU-s on the shared grids) and,
            where some pixel moves by at least :data:`formats.rectify.MIN_CORRECTION_PX` and the
            warps take :data:`WARP_MIN_ERROR_DROP` of the maps' prediction error away, stored,
            and every prediction samples its references through them: the pixels coded are the
            captured ones (``--rectify`` resamples them instead). Off by default (its estimate's
            cost); grids only.
    """

    block_size: int = 16
    key_spacing: int = 0
    key_ratio: float = 0.0
    lam: float = 0.12
    max_disparity: float = 64.0
    step: float | None = None
    lossless: bool = False
    intra_codec: str = "auto"
    search_sample: bool = True
    ablate: tuple = ()
    key_split: int = 0
    weighted: bool = True
    warps: bool = False

    def __post_init__(self):
        check_field_types(self)           # types first: a string or a list fails range tests untyped
        ab = self.ablate
        if isinstance(ab, str) or not isinstance(ab, (tuple, list)) or not set(ab) <= set(ABLATE):
            raise ParameterError(f"ablate must be a list of {', '.join(ABLATE)}, got {ab!r}")
        object.__setattr__(self, "ablate", tuple(sorted(set(ab))))
        if self.intra_codec not in ("auto", "tx", "j2k"):
            raise ParameterError(f"intra codec must be auto, tx or j2k, got {self.intra_codec!r}")
        if not isinstance(self.search_sample, bool):
            raise ParameterError(f"search_sample must be true or false, got {self.search_sample!r}")
        if self.block_size not in (8, 16, 32):
            raise ParameterError(f"tx block size must be 8, 16 or 32, got {self.block_size}")
        if not 0 <= self.key_spacing <= 64:
            raise ParameterError(f"key spacing must be 0 (auto) .. 64, got {self.key_spacing}")
        if not (self.key_ratio == 0 or 1.0 <= self.key_ratio <= 8.0):
            raise ParameterError(f"key ratio must be 0 (auto) or within 1..8, got {self.key_ratio}")
        if not 0 < self.lam <= 10:
            raise ParameterError(f"lam must be within (0, 10], got {self.lam}")
        if not 0 <= self.max_disparity <= 256:
            raise ParameterError(f"max disparity must be within 0..256, got {self.max_disparity}")
        if isinstance(self.key_split, bool) or not isinstance(self.key_split, int) or not 0 <= self.key_split <= 4096:
            raise ParameterError(f"key split must be 0 (auto) .. 4096 streams per key row, got {self.key_split!r}")
        if self.step is not None and not 1 <= self.step <= 1 << 16:
            raise ParameterError(f"step must be within 1..65536, got {self.step}")


def params_info(p: TxParams) -> dict:
    """The parameters as the file's configuration records them (``ablate`` and ``key_split``
    only when set, ``weighted`` only when turned off)."""
    d = asdict(p)
    if d["ablate"]:
        d["ablate"] = list(d["ablate"])
    else:
        del d["ablate"]
    if not d["key_split"]:
        del d["key_split"]
    if d["weighted"]:
        del d["weighted"]
    if not d["warps"]:
        del d["warps"]
    return d
