"""Encoder of the ``tx`` profile: structure, open-loop maps, closed-loop rate-distortion coding
(:class:`TxEncoder`); its parameters are :mod:`rlfc.txparams`, its entropy model
:mod:`rlfc.txmodel`, its quantizer :mod:`rlfc.txquant`, its symbols and file :mod:`rlfc.txpack`;
the search that drives it to a target is :mod:`rlfc.txrate`.

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
from dataclasses import dataclass, replace

import numpy as np

from formats.errors import ParameterError
from formats.metrics import colour_sq_error, psnr_from_sq_error
from formats.parallel import Runner
from formats import parallel as _parallel
from formats.scenes.common import ImageFile, ImageFiles
from formats.viewstack import view_of
from formats.pixels import from_planes, luma_of, rgb_mse_weights, to_planes

from .header import RlfcHeader
from .j2ksearch import smallest_j2k
from .txestimate import estimate_maps, reprice_maps_both
from .txlayout import MAX_REFS
from .txwarp import pair_params, view_offsets, warp_params
from .txpredict import TB, fit_price, fit_weights, priced_weights, mode_weights, planar, predict_tbs, upsample_thumb
from .txsample import KeyAtlas, predict_view
from .txmaps import maps_bytes
from .txsections import pack_thumbs, varints
from .txstructure import build, build_intra
from .txsyntax import MODE_INTRA, MODE_RES, MODE_SKIP, plane_classes
from .txmodel import Model, default_counts
from .txpack import FilePacker
from .txparams import TxParams
from .txquant import RdoQuantizer
from .xp import NUMPY

INTRA_MIN_BITS = 24      # below this a tb's prediction-based cost cannot be beaten by intra coding
#: intra 8×8 blocks are tried only where the block's energy about its mean is below this many
#: times its prediction residual's (measured on the six dense grids at 40 dB: 98.7–99.9% of the
#: blocks that chose intra lie below 4; 0 = try every candidate)
INTRA_ENERGY_RATIO = 4.0
FLUSH_BITS = 20           # a coded block stream's overhead: 3-byte state less the raw bits it carries, padding
#: estimated per-view warps (``warps``) are kept only where they take at least this share of
#: the maps' open-loop luma prediction error away (stanford_chess 32%: −10% bytes at 40 dB;
#: stanford_lytro_general_11 7%, a noisy Lytro grid whose error is mostly noise: +1.3%)
WARP_MIN_ERROR_DROP = 0.15


def auto_spacing(rows: int, cols: int) -> int:
    """Key spacing by grid size (measured on the shared dense grids; BENCHMARKS.md)."""
    return 2 if max(rows, cols) <= 5 else 4


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


class TxEncoder(RdoQuantizer, FilePacker):
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
        from .txcosts import Estimator

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
