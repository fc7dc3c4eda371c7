"""Encoder of the ``tx`` profile: structure, open-loop maps, closed-loop rate-distortion coding
and packing (:class:`TxEncoder`); the search that drives it to a target is :mod:`rlfc.txrate`.

Distortion is measured where PSNR is: YCoCg-R plane errors weighted by their share of the
RGB mean squared error (Y 1, Co 1/6, Cg 1/4; :func:`formats.pixels.rgb_mse_weights`), so each
plane's quantizer step is Δ/√w (equal slopes). Decisions minimise D + λ·R with λ = lam·Δ²
and R from the entropy model of the previous pass (ideal code lengths of the context tables):
per coefficient (round, round − 1 or 0), per plane the last position, per 8×8 block skip /
residual / intra, per random-access block whether a stream (with its 4-byte rANS flush) pays.
Key views use a finer step (Δ / key_ratio): every other view is predicted from them.
"""
from __future__ import annotations

import math
import zlib
from dataclasses import asdict, dataclass, replace

import numpy as np

from formats.codec_api import check_field_types
from formats.errors import ParameterError
from formats.metrics import colour_sq_error, psnr_from_sq_error
from formats.parallel import Runner
from formats import parallel as _parallel
from formats.scenes.common import ImageFile, ImageFiles
from formats.viewstack import view_of
from formats.pixels import from_planes, luma_of, rgb_mse_weights, to_planes

from .header import RlfcHeader
from .transform import COEF_MAX, FORWARD_SCAN as _FWD_SCAN, UNZIG, inverse_float
from .j2ksearch import smallest_j2k
from .txestimate import estimate_maps, reprice_maps_both
from .txlayout import MAX_REFS, SPLIT_VERSION, VERSION, WARP_VERSION, WP_VERSION, TxLayout, weighted_views
from .txwarp import pair_params, view_offsets, warp_params
from .txpredict import TB, fit_price, fit_weights, priced_weights, mode_weights, planar, predict_tbs, upsample_thumb
from .txsample import KeyAtlas, predict_view
from .txmaps import maps_bytes, pack_maps
from .txsections import pack_index, pack_thumbs, stream_order, varints
from .txstructure import build, build_intra
from .txsyntax import (ALPHABET, BAND, ESC, MODE_INTRA, MODE_RES, MODE_SKIP, N_CTX, block_symbols, count_symbols,
                       PACK_CELLS, ctx_esc, ctx_last, ctx_mag, ctx_mode, pack_streams, plane_classes,
                       quantize_counts, tables_from_quantized, tables_to_bytes)
from .xp import NUMPY

#: encoder decisions :attr:`TxParams.ablate` may turn off
ABLATE = ("intra_tbs", "lambda_trim", "maps_reprice", "promote", "rdoq", "ref_modes")
INTRA_MIN_BITS = 24      # below this a tb's prediction-based cost cannot be beaten by intra coding
#: intra 8×8 blocks are tried only where the block's energy about its mean is below this many
#: times its prediction residual's (measured on the six dense grids at 40 dB: 98.7–99.9% of the
#: blocks that chose intra lie below 4; 0 = try every candidate)
INTRA_ENERGY_RATIO = 4.0
#: auto key_split: the shortest estimated key-row stream worth its own state and index entry
KEY_SEGMENT_BYTES = 256
#: auto key_split: a decoder parses the streams of many key rows as lanes in lockstep, one step
#: per symbol of the longest (~30 µs a numpy step on the 2-core box, whatever the lanes), so rows
#: that KEY_SEGMENT_BYTES splits are split further until no stream holds more magnitude symbols
#: than this (a first frame's key rows then parse in ≲ 60 ms), while streams keep at least
#: KEY_MIN_SEGMENT_BYTES. Grids only, and rows that are split already: lytro_dino_2067's rows
#: of one stream at 40 dB split in 3 cost 1.2% and made its first frame slower (42 → 72 ms: lanes
#: instead of one by one); mitsuba_objects_360's (every view intra, a request reads one view's
#: rows) 4 → 8 cost 0.8% and decoded no faster.
KEY_LANE_SYMBOLS = 2048
KEY_MIN_SEGMENT_BYTES = 64
FLUSH_BITS = 20           # a coded block stream's overhead: 3-byte state less the raw bits it carries, padding
PAD = 8
#: estimated per-view warps (``warps``) are kept only where they take at least this share of
#: the maps' open-loop luma prediction error away (stanford_chess 32%: −10% bytes at 40 dB;
#: stanford_lytro_general_11 7%, a noisy Lytro grid whose error is mostly noise: +1.3%)
WARP_MIN_ERROR_DROP = 0.15


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
            reaches), "tx" (thumbnail + transform), or "auto" (j2k without alpha, lossy).
        search_sample: a PSNR target's search codes the key views and every SEARCH_STRIDE-th
            other view (grids with at least SEARCH_MIN_VIEWS other views), then checks the
            chosen step on every view (False: every search pass codes every view).
        ablate: encoder decisions turned off, to measure what each buys (``tools/ablation_tx.py``;
            the decoder is the same): any of :data:`ABLATE` — "ref_modes" (every 8×8 block blends
            its references; no single-reference modes), "rdoq" (levels rounded to nearest, the
            last position is the last nonzero: no rate-distortion quantization), "intra_tbs" (no
            intra 8×8 blocks), "promote" (no view coded alone as a JPEG 2000 key), "lambda_trim"
            (no λ trim between two quantizer steps), "maps_reprice" (the maps' corrections are
            not judged again at the coding λ the probe predicts).
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


def auto_spacing(rows: int, cols: int) -> int:
    """Key spacing by grid size (measured on the shared dense grids; BENCHMARKS.md)."""
    return 2 if max(rows, cols) <= 5 else 4


# -- the entropy model used for decisions ----------------------------------------------------
def default_counts() -> np.ndarray:
    """A plausible first model (before any statistics): mostly skips, small magnitudes."""
    c = np.ones((N_CTX, ALPHABET))
    for kind in range(2):
        for prev in range(4):
            c[ctx_mode(kind, prev), :3] = [60, 30, 3]
    for pc in range(3):
        for mode in (MODE_RES, MODE_INTRA):
            for key in range(2):
                c[ctx_last(pc, mode, key), :65] = np.r_[80, 60 * np.exp(-np.arange(64) / 8)] + 0.1
        for band in range(6):
            for key in range(2):
                for nb in range(4):
                    c[ctx_mag(pc, band, key, nb), :16] = 1000 * np.exp(-np.arange(16) * (1.0 + 0.2 * band)) + 0.1
        c[ctx_esc(pc), :24] = 2.0 ** -np.arange(24) * 1000 + 0.01
    return c


class Model:
    """Code lengths (bits) for decisions, from (N_CTX, ALPHABET) counts (add-one smoothed)."""

    def __init__(self, counts: np.ndarray):
        self.counts = counts                  # (kept: models between two steps interpolate them)
        c = counts + 0.5
        bits = -np.log2(c / c.sum(axis=1, keepdims=True))
        self.mode = np.zeros((2, 3))
        for kind in range(2):
            rows = [ctx_mode(kind, p) for p in range(4)]
            m = c[rows, :3].sum(0)
            self.mode[kind] = -np.log2(m / m.sum())
        self.last = np.zeros((3, 2, 2, 65))
        self.mag = np.zeros((3, 6, 2, 16))
        self.first = np.zeros((3, 6, 2, 16))
        self.esc = np.zeros((3, 24))
        for pc in range(3):
            for mi, mode in enumerate((MODE_RES, MODE_INTRA)):
                for key in range(2):
                    self.last[pc, mi, key] = bits[ctx_last(pc, mode, key), :65]
            for band in range(6):
                for key in range(2):
                    rows = [ctx_mag(pc, band, key, nb) for nb in (1, 2, 3)]
                    m = c[rows, :16].sum(0)
                    self.mag[pc, band, key] = -np.log2(m / m.sum())
                    self.first[pc, band, key] = bits[ctx_mag(pc, band, key, 0), :16]
            self.esc[pc] = bits[ctx_esc(pc), :24]
        self._pos = {}

    def pos_bits(self, pc: int, key: int) -> np.ndarray:
        """(64·16,) magnitude-symbol bits by scan position and symbol (flat), cached."""
        k = (pc, key)
        if k not in self._pos:
            self._pos[k] = np.ascontiguousarray(self.mag[pc, BAND, key]).reshape(-1)
        return self._pos[k]

    def zero_bits(self, pc: int, key: int) -> tuple[np.ndarray, np.ndarray]:
        """(bits of a coded 0 at each scan position (64,) float32, their prefix sums (65,)
        float64), cached: the quantizer's costs."""
        k = (pc, key, 0)
        if k not in self._pos:
            b = self.pos_bits(pc, key)[::16]
            self._pos[k] = (b.astype(np.float32), np.concatenate([[0.0], np.cumsum(b)]))
        return self._pos[k]


def _level_bits(model: Model, l: np.ndarray, pc: int, key: int) -> np.ndarray:
    """Bits of coding magnitudes l (>= 0, (T, 64) in scan order), not the last one: symbol,
    sign, escape bucket and suffix."""
    return _level_bits_at(model, l, np.arange(64)[None, :], pc, key)


def _level_bits_at(model: Model, l: np.ndarray, col: np.ndarray, pc: int, key: int) -> np.ndarray:
    """:func:`_level_bits` of magnitudes ``l`` (>= 0) at scan positions ``col`` (arrays that
    broadcast together: (n,) and (n,), or (T, 64) and (1, 64))."""
    tab = model.pos_bits(pc, key)                           # (64·16,) flat: position·16 + symbol
    b = tab.take(col * 16 + np.minimum(l, ESC)) + (l > 0)
    big = l >= ESC
    if big.any():
        r = l[big] - ESC
        k = np.floor(np.log2(r + 1.0)).astype(np.int64)
        b[big] += model.esc[pc, np.minimum(k, 23)] + k
    return b


#: the forward transform in float32, for the quantizer's decisions
_FWD_SCAN32 = _FWD_SCAN.astype(np.float32)
#: (128, 65) 0/1: [costs coded (T, 64) | costs dropped (T, 64)] @ _PREFIX = the cost of every last
#: position L = 0..64: Σ_{i<L} coded + Σ_{i>=L} dropped
_PREFIX = np.vstack([np.triu(np.ones((64, 65), np.float32), 1), np.tril(np.ones((64, 65), np.float32))])


# -- one view ----------------------------------------------------------------------------------
@dataclass
class ViewCode:
    """Coded form of one view, kept small: tb modes (nloc8,) int8; the levels of the tbs that
    are not skipped only (``tbs`` their indices, ``lv`` (n, P, 64) int16 where they fit, else
    int32, scan order); coded random-access blocks (nloc,) bool; the colour squared error
    against the original (``sse`` over ``cnt`` samples: PSNR without keeping pixels); the
    decoded view as pixels (H, W, C) of the input dtype only when asked for; and, for key views
    (references of others), its planes (Hp, Wp, P) int32."""

    modes: np.ndarray
    tbs: np.ndarray
    lv: np.ndarray
    coded: np.ndarray
    px: np.ndarray | None
    planes: np.ndarray | None = None
    bits: float = 0.0          # the model's estimate of the view's stream bits
    sse: float = 0.0
    cnt: float = 1.0
    wp: np.ndarray | None = None   # (P, 2) gain (1/64) and offset of its weighted prediction, if not the identity

    def levels(self, idx: np.ndarray) -> np.ndarray:
        """(len(idx), P, 64) levels of tbs ``idx`` (zero where skipped)."""
        out = np.zeros((idx.size,) + self.lv.shape[1:], np.int64)
        pos = np.searchsorted(self.tbs, idx)
        hit = (pos < self.tbs.size) & (self.tbs[pos.clip(0, max(self.tbs.size - 1, 0))] == idx) if self.tbs.size \
            else np.zeros(idx.size, bool)
        out[hit] = self.lv[pos[hit]]
        return out


def _dequantize_float(q: np.ndarray, step16: np.ndarray) -> np.ndarray:
    """:func:`rlfc.kernels.dequantize` of (T, p, 64) levels at steps ``step16`` (p,) (1/16),
    clipped to ±COEF_MAX, as float64 (the inverse transform's input): sign(q)·floor((|q|·q16 +
    8) / 16) in floats, exact (|q| < 2^22, q16 < 2^22: every value an integer below 2^53), about
    twice as fast as the int64 arithmetic and its cast."""
    f = q.astype(np.float64)
    a = np.abs(f)
    a *= step16.astype(np.float64)[None, :, None]
    a += 8.0
    a *= 1 / 16
    np.floor(a, out=a)
    np.copysign(a, f, out=a)
    return np.clip(a, -COEF_MAX, COEF_MAX, out=a)


class TxEncoder:
    """Everything independent of the quantizer (planes, structure, maps), and the closed loop."""

    #: hold the final pass's decoded views (:attr:`formats.codec_api.Encoded.decoded`); else its
    #: passes keep each view's error only (``EncodeOptions.keep_decoded``; the same file)
    keep_decoded = True

    def __init__(self, lf, params: TxParams, progress=None, side_lambda: float = 10.0, runner=None,
                 hold_all: bool = False, keep_luma: bool = False):
        """``side_lambda``: luma squared error worth one bit of side information at the quality
        expected (:func:`side_lambda`); ``runner``: where views are coded
        (:class:`formats.parallel.Runner`; None = here, one after another); ``hold_all``: keep
        every view's pixels once read (:meth:`hold`; for encodes whose passes all cover every
        view); ``keep_luma``: keep the views' luma the maps were estimated from until
        :meth:`drop_luma` (for :meth:`reprice_maps`, without reading every view again), where the
        views are read from elsewhere (views in a numpy array give it again for less than holding
        it costs: a third of an RGB light field through the probe pass)."""
        from .profiles.tx import plane_limits

        if lf.views.dtype not in (np.uint8, np.uint16):
            raise ParameterError(f"tx codes 8- or 16-bit views; this light field is {lf.views.dtype}")
        self.lf, self.p, self.runner, self._shared = lf, params, runner, None
        self._hold: frozenset = frozenset()       # views whose pixels are kept once read (hold)
        self._held: dict = {}
        if hold_all:
            self.hold(range(lf.views.shape[0] * lf.views.shape[1]))
        B = params.block_size
        r, c, h, w, ch = lf.views.shape
        self.hdr = RlfcHeader.for_views("tx", r, c, (h, w, ch), lf.views.dtype, B)
        self.Hp, self.Wp = self.hdr.padded
        self.nby, self.nbx = self.hdr.blocks
        self.nby8, self.nbx8 = self.Hp // TB, self.Wp // TB
        self.tpb, self.nt = B // TB, (B // TB) ** 2
        self.h, self.w_px, self.dtype, self.n0 = h, w, lf.views.dtype, r * c
        self.P = ch
        self.pcs = plane_classes(ch)
        self.peak = int(np.iinfo(lf.views.dtype).max)
        self.lo, self.hi, self.flat = plane_limits(ch, self.peak)
        # the bounds tiled over an 8×8 tb (64·P samples): clipping (T, 64·P) views runs numpy's inner
        # loop over a tb, not over P samples (7x faster than broadcasting (P,) bounds, measured)
        self.lo_tb, self.hi_tb = (np.tile(x.astype(np.float64), TB * TB) for x in (self.lo, self.hi))
        # (64·P, P) 0/1: a tb's samples (planes last, flat) → its per-plane sums, as one product
        self._plane_sum = np.tile(np.eye(self.P), (TB * TB, 1))
        self.lo32_tb, self.hi32_tb = self.lo_tb.astype(np.int32), self.hi_tb.astype(np.int32)
        self.w = rgb_mse_weights(ch)
        self.bypass = np.full(ch, params.lossless) | (self.pcs == 2)       # alpha is always exact
        spacing = params.key_spacing or auto_spacing(r, c)
        # posed captures: no grid to predict along, so every view is coded on its own (the
        # transform path or JPEG 2000, whichever is smaller per view)
        self.s = build(r, c, spacing) if lf.layout == "grid" else build_intra(r * c)
        self.warp_report = None                   # what became of asked-for warps (the report's "warps")
        if params.warps and lf.layout == "grid" and r * c >= 2:
            self._estimate_warps(lf)
        elif params.warps:
            self.warp_report = {"applied": False, "reason": "warps are for grids of two or more views; this capture "
                                                            "is coded view by view" if lf.layout != "grid" else
                                "a single view has no warp against a grid"}
        self.warp_dw = None if self.s.warp is None else pair_params(self.s.warp, self.s.refs)
        self.is_key = np.zeros(r * c, bool)
        self.is_key[self.s.keys] = True
        self.intra = (self.s.refs < 0).all(axis=1)
        self.all_intra = bool(self.intra.all() and self.is_key.all())    # (posed captures: no prediction)
        self.key_slot = np.full(r * c, -1, np.int64)
        self.key_slot[self.s.keys] = np.arange(len(self.s.keys))
        ic = params.intra_codec
        if ic == "auto":
            ic = "j2k" if ch in (1, 3) and not params.lossless else "tx"
        if ic == "j2k" and ch not in (1, 3):
            raise ParameterError("JPEG 2000 intra key views need grey or RGB views (alpha must stay exact)")
        self.intra_codec = ic
        self.kr = self.DEFAULT_KEY_RATIO          # until :meth:`auto_key_ratio` has measured one
        self._j2k_hints: dict = {}                # view → what its JPEG 2000 searches learnt (j2ksearch)
        self._map_cost: dict = {}                 # predicted key → bytes of its own map; "all": the section (_map_bytes)
        self._block_means: dict = {}              # intra view → (nby8, nbx8, P) float64 block means
        if progress:
            progress("disparity", 0, None)
        n_maps = len(self.s.cell_views)
        nloc8 = self.nby8 * self.nbx8
        self.side_lambda = side_lambda
        self._maps_before = None                  # the maps as estimated, while repriced (reprice_maps)
        self._repriced = None                     # (λ, reprice_maps_both's result) of the last repricing
        self.has_maps = bool(params.max_disparity > 0 and n_maps)
        self._kept_luma = None
        self._est_costs = None
        if self.has_maps:
            luma = self._luma()

            def estimate():
                return estimate_maps(luma, self.s, max_disparity=params.max_disparity, runner=runner,
                                     side_lambda=side_lambda, progress=progress,
                                     ref_modes="ref_modes" not in params.ablate, with_costs=True)

            self.base, self.disp, self.modes, costs = estimate()
            if self.s.warp is not None and self._warp_error_drop(luma, costs) < WARP_MIN_ERROR_DROP:
                self.s.warp = self.warp_dw = None           # (the maps again, for the views as they are)
                self.warp_report.pop("warp_bytes", None)
                self.warp_report["applied"] = False
                self.base, self.disp, self.modes, costs = estimate()
            self._kept_luma = luma if keep_luma and not isinstance(lf.views, np.ndarray) else None
            self._est_costs = costs if keep_luma else None    # (the repricing's first evaluation)
            del costs
            del luma
        else:
            self.base = np.zeros(nloc8, np.int64)
            self.disp = np.zeros((n_maps, nloc8), np.int64)
            self.modes = np.zeros((n_maps, nloc8), np.int64)

    def _estimate_warps(self, lf) -> None:
        """Each view's warp estimated from the views (``warps``): kept in ``s.warp`` where the
        largest correction reaches :data:`formats.rectify.MIN_CORRECTION_PX`."""
        from formats.rectify import estimate_correction

        est, big, applied = estimate_correction(lf.views)
        h, w = lf.views.shape[2:4]
        if applied:
            self.s.warp = warp_params(est, h, w)
            applied = bool(self.s.warp.any())
            if not applied:
                self.s.warp = None
        self.warp_report = {"applied": applied, "largest_correction_px": round(float(big), 3)}
        if applied:
            self.warp_report["warp_bytes"] = len(zlib.compress(varints(self.s.warp.reshape(-1)), 9))

    def _warp_error_drop(self, luma: np.ndarray, costs: np.ndarray) -> float:
        """The share of the maps' luma prediction error (their chosen modes, open loop) that the
        estimated warps take away: ``costs`` (the estimate's, with the warps, (n_maps, modes,
        nloc8)) against the same maps and modes sampled without them. Recorded in
        ``warp_report`` as ``error_drop``."""
        from .txestimate import Estimator

        plain = Estimator(luma, replace(self.s, warp=None), list(self.s.keys)).costs_maps(self.disp, self.runner)
        pick = self.modes[:, None, :]
        sse_w = float(np.take_along_axis(costs, pick, 1).sum())
        sse_p = float(np.take_along_axis(plain, pick, 1).sum())
        drop = 1.0 - sse_w / sse_p if sse_p > 0 else 0.0
        self.warp_report["error_drop"] = round(drop, 4)
        return drop

    def _luma(self) -> np.ndarray:
        """(n0, Hp, Wp) luma (Y) of every view, in [0, peak], in the views' dtype (the copy kept
        since the maps were estimated, where there is one)."""
        if self._kept_luma is not None:
            return self._kept_luma
        return np.stack([luma_of(self.padded(self.view_pixels(v))) for v in range(self.n0)])

    def drop_luma(self, repriced_too: bool = True) -> None:
        """Let the luma kept for :meth:`reprice_maps` go (a third of an RGB light field), and what
        it last computed (unless not ``repriced_too``: both variants at that λ stay usable)."""
        self._kept_luma = self._est_costs = None
        if repriced_too:
            self._repriced = None

    def reprice_maps(self, side_lambda: float, modes_too: bool = False) -> None:
        """The maps as estimated with their per-cell corrections (and with ``modes_too`` their
        modes) judged again at ``side_lambda`` (larger than the λ they were estimated at:
        :func:`rlfc.txestimate.reprice_maps`), always from the maps as estimated; what was
        measured of the maps before (their bytes per key) is forgotten."""
        if not self.has_maps or side_lambda <= self.estimated_lambda:
            return
        b, d, modes, modes_repriced = self.price_maps_at(side_lambda)
        if self._maps_before is None:
            self._maps_before = self.maps()
        self.use_maps((b, d, modes_repriced if modes_too else modes, side_lambda))

    def price_maps_at(self, side_lambda: float) -> tuple:
        """:func:`rlfc.txestimate.reprice_maps_both` of the maps as estimated at ``side_lambda``,
        from the kept luma, computed once: both variants (corrections, and modes too) come from
        one computation, and :meth:`reprice_maps` at that λ needs no luma afterwards."""
        base, disp, _, lam = self._maps_before or self.maps()
        if self._repriced is None or self._repriced[0] != side_lambda:
            self._repriced = (side_lambda, reprice_maps_both(
                self._luma(), self.s, base, disp, side_lambda=lam, correction_lambda=side_lambda,
                runner=self.runner, ref_modes="ref_modes" not in self.p.ablate, costs=self._est_costs))
        return self._repriced[1]

    def use_maps(self, maps: tuple) -> None:
        """Code with ``maps`` = (base, disp, modes, the λ they were judged at) from here on (one
        of :meth:`reprice_maps`'s results, kept by the caller)."""
        self.base, self.disp, self.modes, self.side_lambda = maps
        self._map_cost = {}
        self._shared = None                       # (workers get the encoder with these maps)

    @property
    def estimated_lambda(self) -> float:
        """The λ the maps were estimated at (before any :meth:`reprice_maps`)."""
        return (self._maps_before or self.maps())[3]

    def maps(self) -> tuple:
        """(base, disp, modes, λ) of the maps coded now (for :meth:`use_maps`)."""
        return self.base, self.disp, self.modes, self.side_lambda

    def restore_maps(self) -> None:
        """The maps as estimated, before :meth:`reprice_maps` (where the step rate control
        settled on did not bear out the λ they were repriced at)."""
        if self._maps_before is not None:
            self.use_maps(self._maps_before)
            self._maps_before = None

    def planes(self, v: int, pixels: np.ndarray | None = None) -> np.ndarray:
        """(Hp, Wp, P) int32 YCoCg-R planes of view v (edge-padded), from ``pixels`` (H, W, C)
        where given (a worker's copy), else from the light field (read when asked: the encoder
        keeps no second copy of the views)."""
        return to_planes(self.padded(self.view_pixels(v) if pixels is None else pixels))

    def padded(self, pixels: np.ndarray) -> np.ndarray:
        """(Hp, Wp, C) a view's (H, W, C) pixels, edges repeated to the padded size."""
        if self.Hp == self.h and self.Wp == self.w_px:
            return np.asarray(pixels)                  # (np.pad copies even with nothing to add)
        pad = ((0, self.Hp - self.h), (0, self.Wp - self.w_px), (0, 0))
        return np.pad(np.asarray(pixels), pad, mode="edge")

    def view_pixels(self, v: int) -> np.ndarray:
        """(H, W, C) pixels of view v (row-major view index): read from the light field, or the
        copy :meth:`hold` keeps."""
        px = self._held.get(v)
        if px is None:
            px = view_of(self.lf.views, v)
            if v in self._hold:
                self._held[v] = px
        return px

    def _worker_views(self, runner, views) -> dict:
        """View → what a worker codes it from: where the views are image files left on this
        machine's disk and the workers run here (a process pool), the file, which the worker reads
        itself (the parent then never holds every view's pixels at once); else the pixels,
        scattered to the workers."""
        files = getattr(self.lf.views, "arr", None)
        if runner.kind == "pool" and isinstance(files, ImageFiles):
            return {int(v): files.file(int(v)) for v in views}
        out: dict = {}
        for a in range(0, len(views), self.SCATTER_VIEWS):      # (a cluster holds what it was sent)
            part = views[a:a + self.SCATTER_VIEWS]
            out.update(zip(part, runner.scatter([self.view_pixels(v) for v in part])))
        return out

    #: views sent to a cluster's workers at a time (:meth:`_worker_views`): the parent never
    #: holds more of them than this for the sending
    SCATTER_VIEWS = 8

    def hold(self, views) -> None:
        """Keep the pixels of ``views`` (row-major indices) once read, and drop any other kept,
        when the light field's views are read from elsewhere (a
        :class:`formats.viewstack.ViewStack` over image files, zarr, dask): the rate search
        re-reads its views at every pass. Views already in memory (a numpy array) are never
        copied. ``hold(())`` lets them all go."""
        lazy = not isinstance(self.lf.views, np.ndarray)
        self._hold = frozenset(int(v) for v in views) if lazy else frozenset()
        self._held = {v: x for v, x in self._held.items() if v in self._hold}

    def __getstate__(self):
        """What a worker needs to code views (:func:`_code_task`): everything but the light
        field and the runner."""
        st = dict(self.__dict__)
        for k in ("lf", "runner", "_shared", "_view_handles", "_held", "_kept_luma", "_est_costs", "_repriced"):
            st.pop(k, None)
        return st

    def __setstate__(self, st):
        self.__dict__.update(st)
        self.lf = self.runner = self._shared = self._kept_luma = self._est_costs = self._repriced = None
        self._held = {}

    # -- steps -----------------------------------------------------------------------------
    DEFAULT_KEY_RATIO = 1.6

    def auto_key_ratio(self, res: dict) -> float:
        """The key views' step ratio from a coded run (high-rate theory): a key's error reaches
        every view that keeps its prediction, scaled by the square of the blend weight, so a
        key's distortion counts π = 1 + Σ_views Σ_refs (w/64)²·κ times (κ the view's fraction of
        skipped 8×8 blocks); with rates ∝ −½·log D the best key step is the others' / √π,
        clipped to [1.2, 2.5] (measured on the six dense grids: BENCHMARKS.md)."""
        s = self.s
        nk = len(s.keys)
        acc, seen = 0.0, 0
        for v in range(len(res["codes"])):
            if self.is_key[v] or res["codes"][v] is None:
                continue
            kappa = float((res["codes"][v].modes == 0).mean())
            w = s.weights[v][s.refs[v] >= 0] / 64.0
            acc += kappa * float((w ** 2).sum())
            seen += 1
        if seen:                         # a run over a sample of the other views stands for all
            acc *= int((~self.is_key).sum()) / seen
        return float(np.clip(np.sqrt(1.0 + acc / max(nk, 1)), 1.2, 2.5))

    def key_ratio(self) -> float:
        return self.p.key_ratio or self.kr

    def steps16(self, step: float) -> np.ndarray:
        """(2, P) steps in 1/16 units: key views, other views."""
        if self.p.lossless:
            return np.full((2, self.P), 16, np.int64)
        wp = np.where(self.w > 0, self.w, 1.0)
        base = step / np.sqrt(wp)
        out = np.stack([base / self.key_ratio(), base])
        out = np.maximum(16, np.rint(out * 16)).astype(np.int64)
        out[:, self.bypass] = 16
        return out

    def grid_step(self, step: float) -> float:
        """The step that codes like ``step`` and lies on the grid of the other views' luma step
        (1/16 units; :meth:`steps16` of both are equal): rate control searches this grid."""
        if self.p.lossless:
            return step
        wp0 = float(self.w[0]) if self.w[0] > 0 else 1.0
        return float(self.steps16(step)[1, 0]) / 16 * math.sqrt(wp0)

    # -- prediction ------------------------------------------------------------------------
    def key_atlas(self, n_keys: int) -> KeyAtlas | None:
        """What :meth:`predict_view` samples, for a pass whose ``n_keys`` key views are not decoded
        yet (the pass stores each key as it is decoded): an empty :class:`rlfc.txsample.KeyAtlas`
        (the remap kernel), or None where OpenCV cannot take the views (the pass then samples a
        planar copy of the key views: :func:`rlfc.txpredict.planar`)."""
        if not KeyAtlas.fits(self.Hp, self.Wp, self.P):
            return None
        return KeyAtlas(n_keys, self.Hp, self.Wp, self.P, KeyAtlas.sample_bits(self.dtype, self.P))

    def predict_view(self, v: int, kp) -> np.ndarray:
        """(Hp, Wp, P) int32 prediction of a view with references from decoded key views ``kp``
        (:meth:`key_atlas`: an atlas, or planar planes); the same integers either way."""
        s = self.s
        m = s.cell[v]
        d, mode = self.disp[m], self.modes[m]
        r0 = s.refs[v].clip(0)
        dpos = s.positions[v] - s.positions[r0]
        warp = None if self.warp_dw is None else view_offsets(self.warp_dw[v], self.nby8, self.nbx8)
        if isinstance(kp, KeyAtlas):                 # raster bands (the decoder's whole-view path)
            return predict_view(kp, self.key_slot[r0], s.weights[v], d, mode, dpos, self.nby8, self.nbx8, warp=warp)
        nloc8 = self.nby8 * self.nbx8
        ty, tx = np.divmod(np.arange(nloc8), self.nbx8)
        w = mode_weights(s.weights[v])[mode]
        slots = np.broadcast_to(self.key_slot[r0], (nloc8, MAX_REFS))
        dy, dx = d[:, None] * dpos[None, :, 0], d[:, None] * dpos[None, :, 1]
        if warp is not None:
            dy, dx = dy + warp[0].reshape(MAX_REFS, -1).T, dx + warp[1].reshape(MAX_REFS, -1).T
        p = predict_tbs(NUMPY, kp, (self.Hp, self.Wp), slots, w, dy, dx, ty * TB, tx * TB)
        return p.reshape(self.nby8, self.nbx8, TB, TB, self.P).transpose(0, 2, 1, 3, 4).reshape(self.Hp, self.Wp, self.P)

    def thumb_levels(self, v: int, thumb16: int, pixels: np.ndarray | None = None) -> np.ndarray:
        """(nby8, nbx8, P) thumbnail levels of an intra view: block means / step, rounded (the
        block means of each view are computed once: every pass asks for them again; from
        ``pixels``, the view's, where given)."""
        o = self._block_means.get(v)
        if o is None:
            o = self._block_means[v] = self.planes(v, pixels).astype(np.float64).reshape(
                self.nby8, TB, self.nbx8, TB, self.P).mean(axis=(1, 3))
        return np.rint(o * 16 / thumb16).astype(np.int64)

    def thumb_pred(self, levels: np.ndarray, thumb16: int) -> np.ndarray:
        return upsample_thumb((levels * thumb16 + 8) >> 4, self.Hp, self.Wp)

    def code_intra(self, k: int, thumb16: int, s16k: np.ndarray, lam_k: float, model: Model,
                   keep_pixels: bool | np.ndarray, pixels: np.ndarray | None = None) -> tuple[np.ndarray, ViewCode]:
        """(thumbnail levels, transform coding) of intra key view k against its thumbnail
        (``keep_pixels``, ``pixels``: as :meth:`code_view`)."""
        lv = self.thumb_levels(k, thumb16, pixels)
        return lv, self.code_view(k, self.thumb_pred(lv, thumb16), s16k, lam_k, model, pixels=pixels,
                                  keep_pixels=keep_pixels)

    # -- coding one view ---------------------------------------------------------------------
    def _tbs(self, img: np.ndarray) -> np.ndarray:
        """(Hp, Wp, P) → (nloc8, 8, 8, P) in raster tb order."""
        return img.reshape(self.nby8, TB, self.nbx8, TB, -1).transpose(0, 2, 1, 3, 4).reshape(-1, TB, TB, img.shape[-1])

    def _untbs(self, t: np.ndarray) -> np.ndarray:
        return t.reshape(self.nby8, self.nbx8, TB, TB, -1).transpose(0, 2, 1, 3, 4).reshape(self.Hp, self.Wp, -1)

    #: tbs quantized at once (the quantizer's float64 temporaries are ~70 bytes per coefficient;
    #: every tb's decisions are its own, so the chunks change no result)
    QUANT_TBS = 1024

    def _quantize(self, r: np.ndarray, step16: np.ndarray, lam: float, model: Model, key: int, mode_cls: int):
        """:meth:`_quantize_tbs` in chunks of QUANT_TBS tbs (bounded temporaries)."""
        T = r.shape[0]
        if T <= self.QUANT_TBS:
            return self._quantize_tbs(r, step16, lam, model, key, mode_cls)
        out = None                    # (each chunk's results written in place: no list of parts to join)
        for a in range(0, T, self.QUANT_TBS):
            part = self._quantize_tbs(r[a:a + self.QUANT_TBS], step16, lam, model, key, mode_cls)
            if out is None:
                out = tuple(np.empty((T,) + x.shape[1:], x.dtype) for x in part)
            for o, x in zip(out, part):
                o[a:a + x.shape[0]] = x
            del part
        return out

    def _quantize_tbs(self, r: np.ndarray, step16: np.ndarray, lam: float, model: Model, key: int, mode_cls: int):
        """RDO quantization of tbs' residuals r (T, 8, 8, P) → (levels (T, P, 64) scan order,
        cost J (T,), distortion-if-skipped D0 (T,), must_code (T,) bool, model bits R (T,)).

        Per coefficient the candidates are round-to-nearest, one less, and 0 (cost
        w·error² + λ·bits); per tb the last coded position is the argmin of the cumulative
        cost (coded below it, dropped above). Tbs none of whose coefficients round away from 0
        skip the search (its result is known: nothing coded).

        The costs are float32 (decisions only: the levels are integers and the reconstruction
        is exact whatever they are), and the 65 cumulative costs of a tb are one product with a
        fixed 0/1 matrix (:data:`_PREFIX`): a float32 GEMM is 2× faster than two float64
        cumulative sums along rows on this box."""
        T = r.shape[0]
        P = self.P
        levels = np.zeros((T, P, 64), np.int32)          # (|levels| < 2^22: coefficients < 2^21·8)
        J = np.zeros(T)
        D0 = np.zeros(T)
        must = np.zeros(T, bool)
        Rb = np.zeros(T)
        tr = np.flatnonzero(~self.bypass)
        if tr.size:                 # the analysis of every transformed plane: one GEMM, scan order out
            rt = np.empty((T, tr.size, 64), np.float32)      # (one cast copy: tb by tb, planes within)
            rv = r.reshape(T, 64, P).transpose(0, 2, 1)
            np.copyto(rt, rv if tr.size == P else rv[:, tr], casting="unsafe")
            Xall = (rt.reshape(-1, 64) @ _FWD_SCAN32).reshape(T, tr.size, 64)
        pos = np.arange(64)
        plain = "rdoq" in self.p.ablate                          # plain rounding (ablation)
        for p in range(P):
            pc = int(self.pcs[p])
            if self.bypass[p]:                                   # exact: levels are the residual samples
                rp = r[..., p].astype(np.float64)
                lv = np.rint(rp.reshape(T, 64) * 16 / step16[p]).astype(np.int64)
                levels[:, p] = lv
                nz = lv != 0
                must |= nz.any(axis=1)
                last = np.where(nz.any(1), 64 - np.argmax(nz[:, ::-1], axis=1), 0)
                bits = _level_bits(model, np.abs(lv), pc, key)
                inside = pos[None, :] < last[:, None]
                rb = (bits * inside).sum(1) + model.last[pc, mode_cls, key, last]
                J += lam * rb
                Rb += rb
                continue
            wgt = self.w[p]
            ip = int(np.searchsorted(tr, p))
            X = Xall[:, ip]
            X2 = X * X
            e = X2.sum(1).astype(np.float64)
            D0 += wgt * e
            if wgt == 0:
                continue
            d = step16[p] / 16.0
            lastb = model.last[pc, mode_cls, key]
            # tbs whose every coefficient rounds to 0 code nothing: J = their error + the bits of
            # "last = 0" (exactly what the search below finds for them), so only the rest search
            # (a comparison then any(): 3.6x faster than a row max on this box, the same tbs: X2 >= 0,
            # and the bound is compared in float32 either way)
            act = np.flatnonzero((X2 >= 0.25 * d * d).any(1))
            idle = np.ones(T, bool)
            idle[act] = False
            J[idle] += wgt * e[idle] + lam * lastb[0]
            Rb[idle] += lastb[0]
            if act.size == 0:
                continue
            Ta = act.size
            xa = X[act]
            ax = np.abs(xa)
            # A = [cost of each coefficient as chosen | cost past the last position (not coded)]
            A = np.empty((Ta, 128), np.float32)
            dz = A[:, 64:]
            np.multiply(X2[act], np.float32(wgt), out=dz)
            zero_bits, zcum = model.zero_bits(pc, key)
            np.add(dz, np.float32(lam) * zero_bits, out=A[:, :64])   # as a coded zero
            # the candidates are evaluated only where rounding gives a nonzero level: where it
            # gives 0 every candidate is 0 and costs exactly the coded zero, so the decisions
            # there are known
            t = ax * np.float32(1.0 / d)
            t += np.float32(0.5)
            nzi = np.flatnonzero(t >= 1.0)                        # flat (Ta·64) indices of ln > 0
            row, col = np.divmod(nzi, 64)
            fa = nzi + (row << 6)                                 # the same places in A
            ln = np.floor(t.ravel()[nzi]).astype(np.int64)
            lo = ln - 1
            a = ax.ravel()[nzi].astype(np.float64)
            b_ln = _level_bits_at(model, ln, col, pc, key)
            b_lo = _level_bits_at(model, lo, col, pc, key)
            j_ln = wgt * (a - ln * d) ** 2 + lam * b_ln
            if plain:
                use_lo, z = np.zeros(nzi.size, bool), np.zeros(nzi.size, bool)
                A.ravel()[fa] = j_ln
            else:
                j_lo = wgt * (a - lo * d) ** 2 + lam * b_lo
                use_lo = j_lo < j_ln
                jmin = np.minimum(j_lo, j_ln)
                j0 = A.ravel()[fa]
                z = j0 <= jmin
                # (a level of 0 costs exactly the coded zero whichever way it was reached)
                A.ravel()[fa] = np.minimum(j0, jmin)
            lvs = (ln - use_lo) * ~z                              # the levels at nzi (0 elsewhere)
            nz = lvs != 0
            # the last position L (coefficients >= L dropped): J(L) = Σ_{i<L} coded + Σ_{i>=L} dz + λ·bits(L),
            # L − 1 nonzero (or L = 0)
            JL = A @ _PREFIX
            JL += (lam * lastb).astype(np.float32)
            if plain:                                             # the last nonzero, whatever it costs
                L = np.zeros(Ta, np.int64)
                np.maximum.at(L, row[nz], col[nz] + 1)
            else:
                last_ok = np.full((Ta, 64), np.inf, np.float32)
                last_ok.ravel()[nzi[nz]] = 0.0
                JL[:, 1:] += last_ok
                L = JL.argmin(1)
            J[act] += JL[np.arange(Ta), L]
            keep = col < L[row]
            # bits of the kept coefficients: the coded zeros' prefix sum, plus the chosen levels'
            # difference from a coded zero
            delta = np.where(use_lo, b_lo, b_ln) - zero_bits[col]
            Rb[act] += zcum[L] + lastb[L] + np.bincount(row, weights=delta * (nz & keep), minlength=Ta)
            lvs = lvs * keep
            lvs *= 1 - 2 * (xa.ravel()[nzi] < 0)                  # the coefficients' signs (a where= ufunc: 4x slower)
            lp = np.zeros((Ta, 64), np.int32)
            lp.ravel()[nzi] = lvs
            levels[act, p] = lp
        return levels, J, D0, must, Rb

    #: tbs reconstructed at once (float64 temporaries of ~40 bytes per sample: 8 MiB at 3 planes;
    #: every tb is its own, so the chunks change no result)
    RECON_TBS = 1024

    def _reconstruct(self, base: np.ndarray, levels: np.ndarray, step16: np.ndarray) -> np.ndarray:
        """(T, 8, 8, P) clipped reconstruction of tbs from base predictions and levels (exact
        decoder integers: the clipped coefficients are below 2^40, so :func:`inverse_float`
        carries them in float64 exactly, and so does the sum with the prediction), in chunks of
        RECON_TBS tbs."""
        T = levels.shape[0]
        if T <= self.RECON_TBS:
            return self._reconstruct_tbs(base, levels, step16)
        out = np.empty(base.shape, np.int32)
        for a in range(0, T, self.RECON_TBS):
            out[a:a + self.RECON_TBS] = self._reconstruct_tbs(base[a:a + self.RECON_TBS],
                                                              levels[a:a + self.RECON_TBS], step16)
        return out

    def _reconstruct_tbs(self, base: np.ndarray, levels: np.ndarray, step16: np.ndarray) -> np.ndarray:
        T, P = levels.shape[0], self.P
        res = np.empty((T, TB, TB, P))
        for planes, tr in ((np.flatnonzero(~self.bypass), True), (np.flatnonzero(self.bypass), False)):
            if planes.size == 0:
                continue
            lv = levels if planes.size == P else levels[:, planes]
            blocks = _dequantize_float(lv[..., UNZIG] if tr else lv, step16[planes]).reshape(T, planes.size, TB, TB)
            if tr:
                blocks = inverse_float(blocks)
            if planes.size == P:
                res[...] = np.moveaxis(blocks, 1, -1)
            else:
                res[..., planes] = np.moveaxis(blocks, 1, -1)
        res += base
        flat = res.reshape(T, TB * TB * P)
        np.minimum(np.maximum(flat, self.lo_tb, out=flat), self.hi_tb, out=flat)
        return res.astype(np.int32)

    def code_view(self, v: int, pred: np.ndarray, step16: np.ndarray, lam: float, model: Model,
                  pixels: np.ndarray | None = None, keep_pixels: bool | np.ndarray = True,
                  lam_fit: float | None = None) -> ViewCode:
        """Rate-distortion coding of one view against its prediction (Hp, Wp, P); ``pixels``
        its (H, W, C) pixels where the caller has them (a worker's copy); ``keep_pixels``: keep
        the decoded pixels (else only their error); an (H, W, C) array: write them there and
        keep that (the pass's one buffer of decoded views); ``lam_fit``: the λ its weighted
        prediction is priced at (default ``lam``; the pass's λ before a trim, so that a trim
        spends its margin on the residuals without turning fits on and off)."""
        key = int(self.is_key[v])
        kind = int(self.intra[v])
        opx = self.view_pixels(v) if pixels is None else pixels
        orig = self._tbs(self.planes(v, opx))
        pt = self._tbs(pred)
        del pred                      # (the caller's temporary: the tb-ordered copy is kept)
        wp = None
        if not kind and self.p.weighted:
            # a weighted prediction (gain and offset per plane) where the fit is not the identity:
            # views exposed differently, noisy predicted chroma (BENCHMARKS.md, weighted prediction)
            # (priced: a plane's fit must take away error worth FIT_PRICE_BITS at this λ)
            # (and only the planes that lower the view's estimated RD cost)
            lf_ = lam if lam_fit is None else lam_fit
            wp = fit_weights(pt, orig, self.lo, self.hi, fit_price(lf_, self.w, pt.shape[0] * TB * TB))
            wp, pt = priced_weights(pt, orig, wp, self.w, lf_, self.lo, self.hi)
        T = orig.shape[0]
        lv_r, J_r, D0_r, must_r, R_r = self._quantize(orig - pt, step16, lam, model, key, 0)
        flat = np.broadcast_to(self.flat.astype(np.int32), orig.shape)
        mb = model.mode[kind]
        J_skip = np.where(must_r, np.inf, D0_r + lam * mb[MODE_SKIP])
        J_res = J_r + lam * mb[MODE_RES]
        # intra only where prediction is expensive: coding even a DC costs more than INTRA_MIN_BITS
        cand = np.flatnonzero(np.minimum(J_skip, J_res) > lam * INTRA_MIN_BITS)
        if cand.size and INTRA_ENERGY_RATIO:
            # and only where the tb's own detail (its energy about its mean, weighted as the error
            # is) is not many times the prediction residual's: intra coding pays that detail
            # (Σx² − (Σx)²/64 per plane: integers and sixty-fourths below 2^47, exact in float64)
            # (the per-plane sums as products with a 0/1 matrix: 4x faster than strided reductions,
            # and exact, as every partial sum is an integer below 2^53)
            oc = orig[cand].reshape(cand.size, TB * TB * self.P).astype(np.float64)
            s1 = oc @ self._plane_sum
            oc *= oc
            ac = (oc @ self._plane_sum - s1 * s1 * (1 / 64)) @ self.w
            cand = cand[ac < INTRA_ENERGY_RATIO * D0_r[cand]]
        if "intra_tbs" in self.p.ablate:
            cand = cand[:0]
        J_int, R_i = np.full(T, np.inf), np.zeros(T)
        lv_c = None
        if cand.size:                 # (levels of the candidates only: lv_c[i] is tb cand[i]'s)
            lv_c, J_c, _, _, R_i[cand] = self._quantize(orig[cand] - flat[cand], step16, lam, model, key, 1)
            J_int[cand] = J_c + lam * mb[MODE_INTRA]
        del orig                      # (what a thread holds at once: the view's codes, its prediction)
        Jm = np.stack([J_skip, J_res, J_int])
        mode = Jm.argmin(0)
        nb = self.nby * self.nbx
        tbi = self._ra_tbs()                                            # (nb, nt) tb indices
        if key:                       # key views: one stream per row of blocks, every block in it
            coded = np.ones(nb, bool)
        else:                         # a block gets a stream only where that pays for its flush and modes
            J_coded = Jm.min(0)[tbi].sum(1) + lam * (FLUSH_BITS + mb[mode[tbi]].sum(1))
            coded = J_coded < J_skip[tbi].sum(1)
            mode[tbi[~coded]] = MODE_SKIP
        # the levels and bases of the tbs that are not skipped (residual or intra)
        live = np.flatnonzero(mode != MODE_SKIP)
        intra = mode[live] == MODE_INTRA
        lv = lv_r[live]
        if intra.any():
            lv[intra] = lv_c[np.searchsorted(cand, live[intra])]
        del lv_r, lv_c
        base = pt[live]
        if intra.any():
            base[intra] = flat[0]
        # predictions blend decoded key views with weights summing to 64, so they are in range
        # (the decoder relies on it too); intra predictions (thumbnails) are clipped
        rec = pt
        if kind:
            flat = rec.reshape(-1, TB * TB * self.P)
            np.minimum(np.maximum(flat, self.lo32_tb, out=flat), self.hi32_tb, out=flat)
        if live.size:                      # skipped tbs are their prediction: reconstruct only the rest
            rec[live] = self._reconstruct(base, lv, step16)
        coded = np.zeros(nb, bool) | coded
        bits = float(np.where(mode == MODE_RES, R_r, np.where(mode == MODE_INTRA, R_i, 0.0)).sum() + mb[mode].sum()
                     + (FLUSH_BITS * coded.sum() if not key else FLUSH_BITS * self.nby))
        planes = self._untbs(rec)
        px = self._pixels(planes)
        sse, cnt = colour_sq_error(opx, px)            # (the planes' pixels: YCoCg-R is exact)
        lv = lv.astype(np.int16 if lv.size == 0 or np.abs(lv).max() < 1 << 15 else np.int32)
        if isinstance(keep_pixels, np.ndarray):
            keep_pixels[...] = px
            px = keep_pixels
        elif not keep_pixels:
            px = None
        return ViewCode(mode.astype(np.int8), live, lv, coded, px,
                        planes if key else None, bits, sse, cnt, wp)

    def _pixels(self, planes: np.ndarray) -> np.ndarray:
        return from_planes(planes[:self.h, :self.w_px], self.dtype)

    def _ra_tbs(self) -> np.ndarray:
        """(nloc, nt) raster tb indices of each random-access block's tbs (tb raster order)."""
        by, bx = np.divmod(np.arange(self.nby * self.nbx), self.nbx)
        t = np.arange(self.nt)
        ty = by[:, None] * self.tpb + t[None, :] // self.tpb
        tx = bx[:, None] * self.tpb + t[None, :] % self.tpb
        return ty * self.nbx8 + tx

    # -- the closed loop -------------------------------------------------------------------------
    def run(self, step: float, model: Model, progress=None, keep_pixels: bool = False, views=None,
            lam_scale: float = 1.0) -> dict:
        """Code every view at luma step Δ = ``step``: key views in order, then the others (only
        those in ``views`` where given: a sample for rate control; the others' codes are None;
        where every view is an intra key, the keys in ``views`` and the first); ``lam_scale``
        multiplies λ (rate control's trim between two quantizer steps).

        Returns:
            dict with steps16, thumb16, thumbs (per intra key), codes (per view ViewCode), kept
            (``keep_pixels`` was asked: the pass a file may be written from, pixels held or not),
            and with ``keep_pixels`` and :attr:`keep_decoded` pixels: the (N0, H, W, C) decoded
            views, which the codes' ``px`` are views of (one buffer: no per-view copies to gather
            at the end).
        """
        s16 = self.steps16(step)
        keep = bool(keep_pixels) and self.keep_decoded      # (the run is "kept" all the same: res["kept"])
        pix = np.empty((self.n0,) + self.lf.views.shape[2:], self.dtype) if keep else None

        # (every view of a posed capture keeps its decoded pixels in its code, so that any pass
        # can be the file's: the intra keys coded ahead do, and so does the first)
        own_px = self.all_intra and self.keep_decoded

        def px_slot(v):             # where view v's decoded pixels go (in this process)
            return pix[v] if pix is not None else own_px

        hints = {k: dict(h) for k, h in self._j2k_hints.items()}     # (a rerun of this pass starts from them)
        lam_k = self.p.lam * lam_scale * (s16[0, 0] / 16.0) ** 2
        lam_n = self.p.lam * lam_scale * (s16[1, 0] / 16.0) ** 2
        n0 = self.n0
        # the decoded key views, for the views predicted from them (none where every view is
        # intra): sampled from an atlas (filled key by key), else (views OpenCV cannot take) from
        # a planar copy of an int32 stack, rebuilt as keys arrive
        kp = keyplanes = None
        if not self.all_intra:
            kp = self.key_atlas(len(self.s.keys))
            if kp is None:
                keyplanes = np.zeros((len(self.s.keys), self.Hp, self.Wp, self.P), np.int32)
                kp = planar(keyplanes)
        codes: list = [None] * n0
        thumbs = {}
        keyimg = {}
        promoted: list = []           # views coded alone as JPEG 2000 that the structure predicts
        j2k_ref = None                # (bytes, PSNR) of the first intra key as JPEG 2000
        thumb16 = None
        trial_counts = None           # symbols of the transform trials of keys coded as JPEG 2000

        def add_trial(tc):
            nonlocal trial_counts
            trial_counts = tc if trial_counts is None else trial_counts + tc
        pre: dict = {}                # intra keys coded ahead, together (every view intra: posed captures)
        keys = self.s.keys
        if views is not None and self.all_intra:       # (every view an intra key: a sample of them, and the first)
            wanted = set(np.asarray(views).tolist())
            keys = [k for k in keys if k == keys[0] or k in wanted]
        # a grid (one intra key, the first; the others predicted, sampled from the atlas): the
        # keys after the first, and the other views, as tasks that wait on their references
        # (:meth:`_dag_pass`; on a few threads), the same integers as one after another
        dag = (isinstance(kp, KeyAtlas) and len(keys) > 1 and bool(self.intra[keys[0]])
               and not self.intra[list(keys[1:])].any())
        for i, k in enumerate(keys):
            if dag and i >= 1:
                break
            if i == 1 and self.all_intra and len(keys) > 2 and (self.intra_codec != "j2k" or j2k_ref):
                pre = self._code_intra_keys(keys[1:], thumb16, s16[0], lam_k, model,
                                             pix if pix is not None else own_px)
            ahead = k in pre
            if ahead:                           # (JPEG 2000 tried there too)
                thumbs[k], codes[k], img, tc = pre.pop(k)
                if img is not None:
                    keyimg[k] = img
                    add_trial(tc)
            elif self.intra[k]:
                # the thumbnail's step (one per file): exact block means (flat regions need no
                # residual at all) or the key step (textured views), whichever costs less (colour
                # squared error + λ·bits) for the first intra view; the others use the same. (By
                # bits alone, a model measured at another step could pick the key step's coarse
                # thumbnail at 6 dB less: hci_antinous at step 120.5, 46 738 bits at 30.4 dB
                # against 50 900 at 36.1.)
                lam_rgb = lam_k * (3.0 if self.P >= 3 else 1.0)   # a luma error e is e in each of R, G, B
                best = None
                cands = [thumb16] if thumb16 is not None else sorted({16, int(s16[0, 0])})
                # (several candidates: each keeps its own pixels, gathered at the end; coded side
                # by side on threads, the same integers, from the view read once here)
                opx = self.view_pixels(k) if len(cands) > 1 else None
                got = Runner().map_threaded(self.code_intra, [(k, t16, s16[0], lam_k, model,
                                                               px_slot(k) if thumb16 is not None else keep or own_px,
                                                               opx) for t16 in cands])
                for t16, (lv, c) in zip(cands, got):
                    cost = c.sse + lam_rgb * (c.bits + 8 * len(pack_thumbs(lv[None])))
                    if best is None or cost < best[0]:
                        best = (cost, t16, lv, c)
                _, thumb16, thumbs[k], codes[k] = best
            else:                               # (as :meth:`_dag_pass` codes them, one after another)
                codes[k], img, tc, _ = _pass_task(self, "key", k, kp, model, s16[0], lam_k, lam_k / lam_scale,
                                                  px_slot(k), j2k_ref, None)
                if img is not None:
                    keyimg[k] = img
                    promoted.append(k)
                    add_trial(tc)
            if not ahead and self.intra[k] and self.intra_codec == "j2k":
                trial = codes[k]
                # (the pass's first key: every other view waits on it, so OpenJPEG gets the threads)
                img, codes[k], size = self._j2k_view(k, codes[k], len(pack_thumbs(thumbs[k][None])),
                                                     self.J2K_KEY_SLACK_DB, give_up=j2k_ref is not None,
                                                     threads=_parallel.LOCAL_THREADS if i == 0 else 1)
                if img is not None:
                    keyimg[k] = img
                    add_trial(self._key_symbols(k, trial, True))
                if j2k_ref is None and size is not None:
                    j2k_ref = (size, self._code_psnr(codes[k]))
            if isinstance(kp, KeyAtlas):
                kp.set(i, codes[k].planes)
            elif keyplanes is not None:
                keyplanes[i] = codes[k].planes
                kp = planar(keyplanes)
            codes[k].planes = None              # (kept once, in the atlas or keyplanes, for this pass only)
            if progress:
                progress("code views", i + 1, n0)
        others = all_others = [v for v in range(n0) if not self.is_key[v]]
        if views is not None:            # a sample of the other views (rate control's search)
            keep = set(int(v) for v in views)
            others = [v for v in others if v in keep]
        runner = self.runner or Runner()
        here = runner.kind == "serial" or runner.workers == 1 or len(others) < 2
        if dag:
            got = self._dag_pass(keys, others if here else [], kp, model, s16, lam_k, lam_n, lam_scale, j2k_ref,
                                 px_slot, progress)
            for k, (code, img, tc) in zip(keys[1:], got):
                codes[k] = code
                if img is not None:
                    keyimg[k] = img
                    promoted.append(k)
                    add_trial(tc)
            for v, c in zip(others if here else [], got[len(keys) - 1:]):
                codes[v] = c
            if here:
                others = []
        done = [len(self.s.keys)]

        def tick(n):
            done[0] += n
            if progress:
                progress("code views", done[0], n0)

        # the other views are independent given the decoded key views: in this process on a few
        # threads (the same integers), else on the runner's workers
        if not others:
            out = []
        elif here:
            out = Runner().map_threaded(_code_task, [(self, kp, model, v, None, s16[1], lam_n, px_slot(v),
                                                    lam_n / lam_scale) for v in others], tick)
        else:
            if self._shared is None:
                self._shared = runner.share(self)
                self._view_handles = self._worker_views(runner, all_others)
            keys_h, model_h = runner.share(kp), runner.share(model)

            def take(i, c):             # a worker's decoded pixels go into the pass's buffer as they arrive
                if pix is not None and c.px is not None:
                    pix[others[i]] = c.px
                    c.px = pix[others[i]]
                return c

            out = runner.map(_code_task, [(self._shared, keys_h, model_h, v, self._view_handles[v], s16[1], lam_n,
                                           keep, lam_n / lam_scale) for v in others], tick, take)
        for v, c in zip(others, out):
            codes[v] = c
        res = {"steps16": s16, "thumb16": thumb16 or 16, "thumbs": thumbs, "codes": codes, "step": step,
               "keyimg": keyimg, "model": model, "promoted": promoted, "j2k_ref": j2k_ref,
               "lam_scale": lam_scale, "j2k_hints": hints, "trial_counts": trial_counts, "kept": bool(keep_pixels)}
        if pix is not None:
            res["pixels"] = pix
            self._gather_pixels(res)
        return res

    def _dag_pass(self, keys: list, others: list, kp: KeyAtlas, model: Model, s16: np.ndarray, lam_k: float,
                  lam_n: float, lam_scale: float, j2k_ref, px_slot, progress) -> list:
        """The predicted keys ``keys[1:]`` (the first, the intra key, is in the atlas) and the views
        ``others``, each a task that starts once the key views it predicts from are decoded
        (:meth:`formats.parallel.Runner.map_dag`: keys first, a few threads; a key's decoded planes
        go into ``kp`` before any view that reads them starts). A key that has never been tried
        as JPEG 2000 starts its search where the intra key's ended (one after another, from the
        previous key's: the order threads finish in must not matter).

        Returns:
            [(code, JPEG 2000 codestream or None, its trial's symbol counts or None) per key after
            the first] + [code per view of ``others``].
        """
        rest = list(keys[1:])
        at = {int(k): i for i, k in enumerate(rest)}
        start = dict(self._j2k_hints.get("last", {}))
        if self.intra_codec == "j2k":
            self._map_bytes(int(rest[0]))          # (made once here, not by two threads at once)
        lam_fit_k, lam_fit_n = lam_k / lam_scale, lam_n / lam_scale
        args, deps = [], []
        for k in rest:
            args.append((self, "key", int(k), kp, model, s16[0], lam_k, lam_fit_k, px_slot(k), j2k_ref, start))
            deps.append([at[int(r)] for r in self.s.refs[k] if r >= 0 and int(r) in at])
        for v in others:
            args.append((self, "view", int(v), kp, model, s16[1], lam_n, lam_fit_n, px_slot(v), None, None))
            deps.append([at[int(r)] for r in self.s.refs[v] if r >= 0 and int(r) in at])
        count = [len(keys) - len(rest)]

        def finish(i, r):
            if i < len(rest):
                k = rest[i]
                kp.set(int(self.key_slot[k]), r[0].planes)
                r[0].planes = None                # (kept once, in the atlas, for this pass only)
            count[0] += 1
            if progress:
                progress("code views", count[0], self.n0)
            return r

        out = Runner().map_dag(_pass_task, args, deps, finish)
        searched = [k for k, r in zip(rest, out) if r[3]]
        if searched:
            self._j2k_hints["last"] = self._j2k_hints[searched[-1]]
        return [r[:3] for r in out[:len(rest)]] + out[len(rest):]

    def run_j2k(self, levels: np.ndarray, step: float, progress=None) -> dict:
        """Every view (a posed capture's: each an intra key) as JPEG 2000 at its own OpenJPEG
        quality ``levels`` (n0,) (dB): a run as :meth:`run` returns it, with no transform-coded
        view (``step`` is only recorded). The views are coded on a few threads (OpenJPEG releases
        the GIL); their decoded pixels are kept where :attr:`keep_decoded` says."""
        keep = self.keep_decoded
        done = [0]

        def tick(n):
            done[0] += n
            if progress:
                progress("code views", done[0], self.n0)

        out = Runner().map_threaded(_j2k_task, [(self, v, float(levels[v]), keep) for v in range(self.n0)], tick)
        res = {"steps16": self.steps16(step), "thumb16": 16, "thumbs": {}, "codes": [c for _, c in out], "step": step,
               "keyimg": {v: data for v, (data, _) in enumerate(out)}, "model": Model(default_counts()),
               "promoted": [], "j2k_ref": None, "lam_scale": 1.0, "j2k_hints": {}, "trial_counts": None,
               "kept": True}
        if keep:
            res["pixels"] = np.empty((self.n0,) + self.lf.views.shape[2:], self.dtype)
            self._gather_pixels(res)
        return res

    @staticmethod
    def _gather_pixels(res: dict) -> None:
        """Copy into ``res["pixels"]`` the decoded views that live elsewhere (JPEG 2000 views,
        workers' results) and make their codes' ``px`` views of it."""
        pix = res["pixels"]
        for v, c in enumerate(res["codes"]):
            if c is not None and c.px is not None and not np.may_share_memory(c.px, pix):
                pix[v] = c.px
                c.px = pix[v]

    def _code_intra_keys(self, ks: list, thumb16: int, s16k: np.ndarray, lam_k: float, model: Model,
                         keep_pixels: np.ndarray | bool | None) -> dict:
        """Intra key views ``ks`` after the first (which chose the thumbnail step and the JPEG 2000
        reference), coded as the pass would code them one by one, on a few threads (``keep_pixels``:
        the pass's buffer of decoded views, or None to keep none): view →
        (thumbnail levels, code, JPEG 2000 codestream or None, symbol counts of the transform
        trial where JPEG 2000 won, else None). A view's JPEG 2000 search with no
        hint of its own starts from the first view's (one after another, from the previous
        view's: the order threads finish in must not matter)."""
        first = dict(self._j2k_hints.get("last", {}))
        for k in ks:
            self._j2k_hints.setdefault(k, dict(first))
        out = Runner().map_threaded(_intra_key_task, [(self, k, thumb16, s16k, lam_k, model,
                                                       keep_pixels[k] if isinstance(keep_pixels, np.ndarray) else
                                                       keep_pixels) for k in ks])
        if ks:
            self._j2k_hints["last"] = self._j2k_hints[ks[-1]]
        return dict(zip(ks, out))

    #: a JPEG 2000 intra key may land this much (dB) below its transform coding's PSNR (the
    #: rate control measures the decoded views, whichever codec made them)
    J2K_KEY_SLACK_DB = 0.05
    #: a view is tried as JPEG 2000 only where its transform coding costs at least this share of
    #: the JPEG 2000 size the run's intra key predicts for it (a gate, so that grids whose views
    #: predict well spend no JPEG 2000 encodes)
    J2K_TRY_SHARE = 0.85

    def _j2k_view(self, v: int, tx_code: ViewCode, extra_bytes: float, slack_db: float,
                  give_up: bool = True, start: dict | None = None,
                  threads: int = 1) -> tuple[bytes | None, ViewCode, float | None]:
        """View v as JPEG 2000 (its padded Hp×Wp image) with colour error at most its transform
        coding's (less ``slack_db``), where that is smaller than the transform path (the model's
        estimate of its streams + ``extra_bytes``); else (None, the transform coding).

        Returns:
            (codestream or None, the view's code, bytes of the smallest JPEG 2000 that met the
            budget where the search found one, else None; with ``give_up=False`` the search
            does not stop at the transform path's size, so the size is there for reference;
            ``start``: where a view not searched before starts, instead of the last view
            searched, which is then left as it is; ``threads``: OpenJPEG's, for a search
            that runs alone).
        """
        orig = self.view_pixels(v)
        budget = tx_code.sse * 10 ** (slack_db / 10)
        target = self._code_psnr(tx_code)
        tx_bytes = tx_code.bits / 8 + extra_bytes

        def err(dec):
            return colour_sq_error(orig, dec[:self.h, :self.w_px])[0]

        # where OpenJPEG lands for this view, kept across the passes of rate control (a view not
        # searched before starts from the last view's)
        hint = self._j2k_hints.setdefault(v, dict(self._j2k_hints.get("last", {}) if start is None else start))
        found = smallest_j2k(self.padded(orig), budget, err, target, tx_bytes if give_up else math.inf, hint,
                             threads=threads)
        if start is None:
            self._j2k_hints["last"] = hint
        if found is None or len(found[0]) >= tx_bytes:
            return None, tx_code, (len(found[0]) if found is not None else None)
        data, dec = found
        rec = to_planes(dec)
        crop = self._pixels(rec)                      # the view's own size (the image coded is padded)
        sse, cnt = colour_sq_error(orig, crop)
        return data, self.image_code(crop, rec, sse, cnt), len(data)

    def image_code(self, px: np.ndarray | None, planes: np.ndarray | None, sse: float, cnt: float) -> ViewCode:
        """The code of a view coded alone as an image (JPEG 2000): no tbs, no coded block; its
        decoded pixels and planes where kept, its colour squared error ``sse`` over ``cnt``."""
        return ViewCode(np.zeros(self.nby8 * self.nbx8, np.int8), np.zeros(0, np.int64),
                        np.zeros((0, self.P, 64), np.int16), np.zeros(self.nby * self.nbx, bool), px, planes,
                        0.0, sse, cnt)

    def _code_psnr(self, code: ViewCode) -> float:
        """Colour PSNR (dB) of one coded view."""
        return 10 * math.log10(float(self.peak) ** 2 * code.cnt / max(code.sse, 1e-30))

    def _j2k_worth_trying(self, code: ViewCode, ref: tuple | None, extra_bytes: float = 0.0) -> bool:
        """Whether a view coded as ``code`` (plus ``extra_bytes`` of side information it alone
        needs) might be smaller as JPEG 2000, from ``ref`` = (bytes, PSNR) of the run's intra key
        as JPEG 2000: about twice the bytes per 6 dB."""
        if ref is None or code.sse <= 0:
            return False
        return code.bits / 8 + extra_bytes >= self.J2K_TRY_SHARE * ref[0] * 2.0 ** ((self._code_psnr(code) - ref[1]) / 6.0)

    def _map_bytes(self, k: int) -> float:
        """Bytes of the maps section that predicted key k's own map costs (its cell holds k
        alone: coded alone as JPEG 2000, the key frees it): the section's size with and without
        that map, for every such key at once on the first call (estimated:
        :func:`rlfc.txmaps.maps_bytes`, as the transform path's streams are); 0 where the cell
        has other views."""
        if not self._map_cost:                   # every such key at once
            alone = [(int(v), int(self.s.cell[v])) for v in self.s.keys
                     if self.s.cell[v] >= 0 and list(self.s.cell_views[int(self.s.cell[v])]) == [v]]
            variants = [(self.disp, self.modes)]
            for _, c in alone:
                disp, modes = self.disp.copy(), self.modes.copy()
                disp[c], modes[c] = self.base, 0
                variants.append((disp, modes))
            sizes = maps_bytes(self.base, variants, (self.nby8, self.nbx8))
            self._map_cost = {"all": sizes[0], **{v: float(sizes[0] - n) for (v, _), n in zip(alone, sizes[1:])}}
        return self._map_cost.get(k, 0.0)

    def promote_views(self, res: dict, limits=None) -> list:
        """Code as JPEG 2000 every view that is not a key view whose transform coding is larger
        than JPEG 2000 at no more error (noise-dominated captures at high rates): it becomes an
        intra key view (decoded whole when a request first needs it, no stream, no map), appended to the key
        order; nothing else changes (no view is predicted from it). Keeps the key views within
        the open-time pixel limit. Changes ``res`` in place; returns the views promoted."""
        from formats.limits import DEFAULT

        ref = res.get("j2k_ref")
        if ref is None or self.intra_codec != "j2k":
            return []
        cap = (limits or DEFAULT).max_open_pixels // (self.Hp * self.Wp) - len(self.s.keys)
        done = []
        for v in range(self.n0):
            c = res["codes"][v]
            if len(done) >= cap or self.is_key[v] or c is None or not self._j2k_worth_trying(c, ref):
                continue
            img, code, _ = self._j2k_view(v, c, 1.5 * float(c.coded.sum()), 0.0)
            if img is not None:
                res["codes"][v] = code
                res["keyimg"][v] = img
                done.append(v)
        res["promoted"] = res.get("promoted", []) + done
        return done

    def decoded(self, res: dict) -> np.ndarray | None:
        """(R, C, H, W, Ch) pixels of a run (the run again, keeping pixels, where it kept none:
        the same integers): the run's buffer, with the views coded after it (promoted views);
        None where the encoder keeps no decoded views (``keep_decoded``)."""
        if not self.keep_decoded:
            return None
        res = self.with_pixels(res)
        self._gather_pixels(res)
        return res["pixels"].reshape(self.lf.views.shape)

    def with_pixels(self, res: dict) -> dict:
        """``res``, or the same run again keeping the decoded pixels where it kept none (the
        same integers); without ``keep_decoded``, the same run over every view where it covered
        a sample only."""
        if any(c is None for c in res["codes"]) or self.keep_decoded and any(c.px is None for c in res["codes"]):
            # the JPEG 2000 searches start where they started in that pass: the same codestreams
            self._j2k_hints = {k: dict(h) for k, h in res.get("j2k_hints", {}).items()}
            return self.run(res["step"], res["model"], keep_pixels=True, lam_scale=res.get("lam_scale", 1.0))
        if self.keep_decoded and "pixels" not in res:      # every view's pixels kept in its code (key views: a posed capture)
            res = dict(res, pixels=np.empty((self.n0,) + self.lf.views.shape[2:], self.dtype))
            self._gather_pixels(res)
        return res

    def psnr(self, res: dict) -> float:
        """Colour PSNR of a run over all views (exactly :func:`formats.metrics.psnr_rgb`); of a
        run over a sample of the other views (``run(views=...)``), the estimate that counts each
        sampled view for the other views it stands for (key views exactly)."""
        c = res["codes"]
        done = [v for v, x in enumerate(c) if x is not None]
        w = np.ones(len(done))
        sampled = [i for i, v in enumerate(done) if not self.is_key[v]]
        n_other = int((~self.is_key).sum())
        if len(done) < len(c) and sampled:
            w[sampled] = n_other / len(sampled)
        return psnr_from_sq_error(w * np.array([c[v].sse for v in done]), w * np.array([c[v].cnt for v in done]),
                                  float(self.peak))

    def view_psnrs(self, res: dict) -> np.ndarray:
        """(views,) colour PSNR of each view of a run over every view (inf where exact; exactly
        :func:`formats.metrics.psnr_views` of its decoded views)."""
        return np.array([psnr_from_sq_error(c.sse, c.cnt, float(self.peak)) for c in res["codes"]])

    # -- symbols and packing -----------------------------------------------------------------
    SYMBOL_CHUNK = 1024        # random-access blocks turned into symbols at a time (bounds memory)

    def coded_blocks(self, res: dict) -> np.ndarray:
        """(n0, nloc) bool: the random-access blocks of the views that are not key views that
        have a stream."""
        coded = np.zeros((self.n0, self.nby * self.nbx), bool)
        for v, c in enumerate(res["codes"]):
            if not self.is_key[v] and c is not None:
                coded[v] = c.coded
        return coded

    def symbol_parts(self, res: dict, counts_only: bool = False, split: int = 1):
        """Every stream's symbols, in ``tx.blocks`` order (the key views' rows, then the other
        views' coded blocks, location-major), a part at a time: yields (lanes in the part,
        symbols of :func:`rlfc.txsyntax.block_symbols` with lanes numbered within the part).
        Parts are one key view, or up to SYMBOL_CHUNK blocks of the others, so that symbols
        of a high-rate light field never all exist at once. ``counts_only``: each part's symbol
        counts instead (no ordering, no raw bits). ``split``: streams per key row."""
        tbi = self._ra_tbs()
        for k in self.coded_keys(res):                   # key rows: split lanes of nbx·nt/split tbs each
            yield self.nby * split, self._key_symbols(k, res["codes"][k], counts_only, split)
        sv, sl = stream_order(self.coded_blocks(res))     # location-major, views ascending
        for a in range(0, sv.size, self.SYMBOL_CHUNK):
            v_, l_ = sv[a:a + self.SYMBOL_CHUNK], sl[a:a + self.SYMBOL_CHUNK]
            modes = np.zeros((v_.size, self.nt), np.int64)
            levels = np.zeros((v_.size, self.nt, self.P, 64), np.int64)
            for v in np.unique(v_).tolist():
                i = np.flatnonzero(v_ == v)
                c = res["codes"][v]
                modes[i] = c.modes[tbi[l_[i]]]
                levels[i] = c.levels(tbi[l_[i]].reshape(-1)).reshape(i.size, self.nt, self.P, 64)
            yield v_.size, block_symbols(modes, levels, self.intra[v_].astype(np.int64), np.zeros(v_.size, np.int64),
                                         self.pcs, counts_only)

    def _key_symbols(self, k: int, c: ViewCode, counts_only: bool = False, split: int = 1):
        """The symbols of key view k coded as ``c``: ``split`` lanes per block row (nbx·nt/split
        tbs each, the row's blocks in order), as :func:`rlfc.txsyntax.block_symbols` gives them
        (``counts_only``: their counts)."""
        tbi = self._ra_tbs()
        n, seg = self.nby * split, self.nbx * self.nt // split
        modes = c.modes[tbi].astype(np.int64).reshape(n, seg)
        levels = c.levels(tbi.reshape(-1)).reshape(n, seg, self.P, 64)
        return block_symbols(modes, levels, np.full(n, int(self.intra[k])), np.ones(n, np.int64),
                             self.pcs, counts_only)

    def key_split(self, res: dict) -> int:
        """Streams per key-view block row for the file of a run: ``TxParams.key_split`` (the
        largest divisor of the blocks per row not above it), or, when 0, the most streams whose
        estimated length stays at least :data:`KEY_SEGMENT_BYTES` (each costs a 3-byte state and
        an index entry; a decoder parses a row's streams as parallel lanes). Where that splits
        the rows of a grid, more while the longest stream would hold over
        :data:`KEY_LANE_SYMBOLS` magnitude symbols (the decoder's steps), in streams of at least
        :data:`KEY_MIN_SEGMENT_BYTES`."""
        divs = [d for d in range(1, self.nbx + 1) if self.nbx % d == 0]
        if self.p.key_split:
            return max(d for d in divs if d <= self.p.key_split)
        ck = self.coded_keys(res)
        if not ck:
            return 1
        row_bytes = sum(res["codes"][k].bits for k in ck) / 8 / (len(ck) * self.nby)
        split = max(d for d in divs if d == 1 or row_bytes / d >= KEY_SEGMENT_BYTES)
        if split == 1 or self.all_intra:    # (see KEY_LANE_SYMBOLS)
            return split
        blocks = np.stack([self._block_symbols(res["codes"][k]) for k in ck])      # (keys, nby, nbx)
        for d in divs:
            if d <= split:
                continue
            if (blocks.reshape(len(ck), self.nby, split, -1).sum(3).max() <= KEY_LANE_SYMBOLS
                    or row_bytes / d < KEY_MIN_SEGMENT_BYTES):
                break
            split = d
        return split

    def _block_symbols(self, c: ViewCode) -> np.ndarray:
        """(nby, nbx) magnitude symbols of each random-access block of a coded view: the tbs'
        last positions (1 + the last nonzero level's scan index), summed over planes and tbs."""
        per_tb = np.zeros(self.nby8 * self.nbx8, np.int64)
        if c.tbs.size:
            nz = c.lv != 0
            per_tb[c.tbs] = np.where(nz.any(-1), 64 - np.argmax(nz[..., ::-1], -1), 0).sum(1)
        return per_tb[self._ra_tbs()].sum(1).reshape(self.nby, self.nbx)

    def counts_of(self, res: dict, split: int = 1) -> np.ndarray:
        """(N_CTX, ALPHABET) symbol counts of a run (part by part; ``split`` streams per key row)."""
        total = None
        for _, c in self.symbol_parts(res, counts_only=True, split=split):
            total = c if total is None else total + c
        return total if total is not None else count_symbols(np.zeros(0, np.int64), np.zeros(0, np.int64))

    def coded_keys(self, res: dict) -> list:
        """Key views coded as row streams (not JPEG 2000), in key order."""
        return [k for k in self.s.keys if k not in res["keyimg"] and res["codes"][k] is not None]

    def structure_of(self, res: dict):
        """(keys, refs, weights, cell, intra) of a run: the plan with the views it coded alone
        as JPEG 2000 (``res["promoted"]``) made intra keys (no references, no map); promoted
        views that were not keys come after the planned keys, in view order."""
        promoted = [int(v) for v in res.get("promoted", ())]
        refs, weights, cell = self.s.refs.copy(), self.s.weights.copy(), self.s.cell.copy()
        refs[promoted], weights[promoted], cell[promoted] = -1, 0, -1
        keys = list(self.s.keys) + sorted(v for v in promoted if not self.is_key[v])
        return keys, refs, weights, cell, (refs < 0).all(axis=1)

    def model_of(self, res: dict) -> Model:
        """The entropy model the next pass decides with: this pass's symbol counts, plus those
        of the transform trials of key views that JPEG 2000 coded. Without them the intra
        contexts had no counts: the next pass's trial of the intra key, with costs from the
        smoothing alone, could code it at a much lower quality, which JPEG 2000 then matched
        (hci_antinous at step 84.9: the intra key 32.3 dB instead of 37.6, every view 2.2 dB
        lower)."""
        c = self.counts_of(res)
        if res.get("trial_counts") is not None:
            c = c + res["trial_counts"]
        return Model(c + default_counts() * 1e-3)

    def weights_of(self, res: dict) -> np.ndarray:
        """(N0, P, 2) the gains and offsets of a run's weighted predictions, as its file records
        them (the identity, gain 64 and offset 0, for views without one and for intra views)."""
        intra = self.structure_of(res)[4]
        wp = np.zeros((self.n0, self.P, 2), np.int64)
        wp[..., 0] = 64
        for v, c in enumerate(res["codes"]):
            if c is not None and c.wp is not None and not intra[v]:
                wp[v] = c.wp
        return wp

    def pack(self, res: dict) -> tuple[dict, list]:
        """(config, sections) of a run: the tables from every part's counts, then each part's
        streams (a lane's bytes depend on its own symbols and the tables only)."""
        split = self.key_split(res)
        q = quantize_counts(self.counts_of(res, split))
        tables = tables_from_quantized(q)
        streams: list = []
        # parts are coded together until lanes × longest lane reaches PACK_CELLS (a lane's bytes
        # depend on its own symbols only): a key view's few long row streams alone would make
        # thousands of rANS steps of a dozen lanes each
        held: list = []                                  # (lanes, longest lane, part)

        def flush():
            if held:
                off = np.cumsum([0] + [n for n, _, _ in held[:-1]]).tolist()      # (python ints keep the lanes' types)
                cat = [np.concatenate([p[i] + (o if i in (0, 3) else 0) for o, (_, _, p) in zip(off, held)])
                       for i in range(5)]
                streams.extend(pack_streams(sum(n for n, _, _ in held), *cat, tables))
                held.clear()

        for n, part in self.symbol_parts(res, split=split):
            k = int(np.bincount(part[0], minlength=1).max()) if part[0].size else 0
            if held and (sum(h[0] for h in held) + n) * max(k, *(h[1] for h in held)) > PACK_CELLS:
                flush()
            held.append((n, k, part))
        flush()
        coded = self.coded_blocks(res)
        ck = self.coded_keys(res)
        keys, refs, weights, cell, intra = self.structure_of(res)
        nk = len(ck) * self.nby * split
        key_lengths = np.array([len(b) for b in streams[:nk]], np.int64)
        lengths = np.array([len(b) for b in streams[nk:]], np.int64)
        ordered = streams
        intra_keys = [k for k in ck if intra[k]]
        imgs = [res["keyimg"][k] for k in keys if k in res["keyimg"]]
        # one entry per intra key (0 = that view is transform-coded) when any is JPEG 2000
        key_images = tuple(len(res["keyimg"][k]) if k in res["keyimg"] else 0
                           for k in keys if intra[k]) if imgs else ()
        thumbs = np.stack([res["thumbs"][k] for k in intra_keys]) if intra_keys else \
            np.zeros((0, self.nby8, self.nbx8, self.P), np.int64)
        wp = self.weights_of(res)
        weighted = bool(weighted_views(wp).any())
        warped = self.s.warp is not None                # (version 5: version 4's tables, then the warps)
        lay = TxLayout(self.s.positions, tuple(keys), refs, weights, cell,
                       len(self.s.cell_views), res["steps16"], self.bypass, res["thumb16"],
                       "j2k" if imgs else "tx", key_images,
                       WARP_VERSION if warped else WP_VERSION if weighted else SPLIT_VERSION if split > 1 else VERSION,
                       split, wp if weighted or warped else None, self.s.warp)
        lay.check("tx encoder")
        # maps no view uses any more (every view of the cell coded alone): the shared map, no modes
        disp, modes = self.disp, self.modes
        unused = np.setdiff1d(np.arange(len(self.s.cell_views)), cell[cell >= 0])
        if unused.size:
            disp, modes = disp.copy(), modes.copy()
            disp[unused], modes[unused] = self.base[None, :], 0
        cfg = {**self.hdr.to_config(), "tx": lay.to_config(),
               "params": {**params_info(self.p), "step": res["step"], "lam_scale": res.get("lam_scale", 1.0)},
               "n_blocks": int(coded.sum()), "n_key_views": len(keys)}
        sections = [("tx.layout", lay.to_bytes()), ("tx.tables", tables_to_bytes(q)),
                    ("tx.maps", pack_maps(self.base, disp, modes, (self.nby8, self.nbx8))),
                    ("tx.thumbs", pack_thumbs(thumbs)), ("tx.keyimg", b"".join(imgs)),
                    ("tx.index", pack_index(key_lengths, coded, lengths)),
                    ("tx.blocks", b"".join(ordered) + bytes(PAD))]
        return cfg, sections


def _dct_task(enc: TxEncoder, v: int) -> tuple[tuple[np.ndarray, int], float]:
    """(:func:`rlfc.j2kalloc.dct_samples`, :func:`rlfc.j2kalloc.smooth_psnr`) of view v."""
    from .j2kalloc import dct_samples, smooth_psnr

    px = enc.view_pixels(v)
    return dct_samples(px), smooth_psnr(px)


def _j2k_task(enc: TxEncoder, v: int, level: float, keep: bool) -> tuple[bytes, ViewCode]:
    """View v's padded image as JPEG 2000 at OpenJPEG's quality ``level`` (dB): (codestream,
    its code: no tbs, the colour error over the view's own pixels, the pixels where ``keep``)."""
    import imagecodecs

    from .topcodec import decode_image

    orig = enc.view_pixels(v)
    img = enc.padded(orig)
    data = bytes(imagecodecs.jpeg2k_encode(img[..., 0] if img.shape[-1] == 1 else img, level=level,
                                           codecformat="J2K"))
    crop = decode_image("j2k", data, img.shape, img.dtype)[:enc.h, :enc.w_px]
    sse, cnt = colour_sq_error(orig, crop)
    return data, enc.image_code(np.ascontiguousarray(crop) if keep else None, None, sse, cnt)


def _code_task(enc: TxEncoder, kp: np.ndarray, model: Model, v: int, pixels: np.ndarray,
               step16: np.ndarray, lam: float, keep_pixels, lam_fit: float | None = None) -> ViewCode:
    """One view that is not a key view, coded on a worker (the same integers as in the parent);
    ``kp`` the pass's decoded key views (:meth:`TxEncoder.key_atlas`, or planar planes);
    ``keep_pixels``, ``lam_fit`` as :meth:`TxEncoder.code_view`; ``pixels`` the view's (H, W, C)
    pixels or its image file (read here)."""
    if isinstance(pixels, ImageFile):
        pixels = pixels.read()
    return enc.code_view(v, enc.predict_view(v, kp), step16, lam, model, pixels, keep_pixels, lam_fit)


def _pass_task(enc: TxEncoder, what: str, v: int, kp: KeyAtlas, model: Model, step16: np.ndarray, lam: float,
               lam_fit: float, keep_pixels, j2k_ref, start) -> tuple | ViewCode:
    """One task of :meth:`TxEncoder._dag_pass`: a view that is not a key view (its code), or a
    predicted key view: (its code, kept with its decoded planes; the JPEG 2000 codestream where
    coding it alone as JPEG 2000 is smaller (``j2k_ref``: the pass's intra key as JPEG 2000),
    else None; that case's transform trial's symbol counts; whether JPEG 2000 was tried;
    ``start``: where a first JPEG 2000 search starts, None: where the last one ended)."""
    code = _code_task(enc, kp, model, v, None, step16, lam, keep_pixels, lam_fit)
    if what == "view":
        return code
    img = tc = None
    tried = enc.intra_codec == "j2k" and enc._j2k_worth_trying(code, j2k_ref, enc._map_bytes(v))
    if tried:
        # a predicted key that costs more than coding it alone (its streams and the map that
        # only it uses) becomes an intra key
        trial = code
        img, code, _ = enc._j2k_view(v, code, enc._map_bytes(v), enc.J2K_KEY_SLACK_DB, start=start)
        if img is not None:
            tc = enc._key_symbols(v, trial, True)
    return code, img, tc, tried


def _intra_key_task(enc: TxEncoder, k: int, thumb16: int, s16k: np.ndarray, lam_k: float, model: Model,
                    keep_pixels) -> tuple:
    """One intra key view that is not the first of its pass (:meth:`TxEncoder._code_intra_keys`)."""
    lv, code = enc.code_intra(k, thumb16, s16k, lam_k, model, keep_pixels)
    img = tc = None
    if enc.intra_codec == "j2k":
        trial = code
        img, code, _ = enc._j2k_view(k, code, len(pack_thumbs(lv[None])), enc.J2K_KEY_SLACK_DB, give_up=True)
        if img is not None:             # (the next pass's model counts the transform trial)
            tc = enc._key_symbols(k, trial, True)
    code.planes = None                  # (no view is predicted from it)
    return lv, code, img, tc


__all__ = ["TxParams", "TxEncoder", "Model", "default_counts"]
