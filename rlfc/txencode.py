"""Encoder of the ``tx`` profile: structure, open-loop maps, closed-loop rate-distortion coding
(:class:`TxEncoder`); its parameters are :mod:`rlfc.txparams`, its entropy model
:mod:`rlfc.txmodel`, its quantizer :mod:`rlfc.txquant`, its symbols and file :mod:`rlfc.txpack`;
its closed-loop passes :mod:`rlfc.txpass`, its views coded alone as JPEG 2000
:mod:`rlfc.txj2kview`; the search that drives it to a target is :mod:`rlfc.txrate`.

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
from formats.metrics import colour_sq_error
from formats.scenes.common import ImageFiles
from formats.viewstack import view_of
from formats.pixels import from_planes, luma_of, rgb_mse_weights, to_planes

from .header import RlfcHeader
from .txestimate import estimate_maps, reprice_maps_both
from .txlayout import MAX_REFS
from .txwarp import pair_params, view_offsets, warp_params
from .txpredict import TB, fit_price, fit_weights, priced_weights, mode_weights, predict_tbs, upsample_thumb
from .txsample import KeyAtlas, predict_view
from .txsections import varints
from .txstructure import build, build_intra
from .txsyntax import MODE_INTRA, MODE_RES, MODE_SKIP, plane_classes
from .txmodel import Model, default_counts
from .txj2kview import J2kViews
from .txpack import FilePacker
from .txpass import PassCoder
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


class TxEncoder(PassCoder, J2kViews, RdoQuantizer, FilePacker):
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
            ic = "tx" if params.lossless else "j2k"
        self.intra_codec = ic                     # (views with alpha: JPEG 2000 colour, exact alpha after it)
        self._alpha: dict = {}                    # view → its alpha stream (alpha_stream_of)
        self.kr = self.DEFAULT_KEY_RATIO          # until :meth:`auto_key_ratio` has measured one
        self._j2k_hints: dict = {}                # view → what its JPEG 2000 searches learnt (j2ksearch)
        self._thumb_at: dict = {}                 # key step (1/16) → the thumbnail step an earlier pass chose there
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

    def alpha_stream_of(self, v: int) -> bytes:
        """View v's alpha stream (:func:`rlfc.topcodec.alpha_stream` of its padded alpha plane),
        which ends its JPEG 2000 image entry; b"" for views without alpha. Made once per view
        (every JPEG 2000 search and level pass of the view, and the packer, take it from here)."""
        from .topcodec import alpha_stream

        if not self.lf.has_alpha:
            return b""
        a = self._alpha.get(v)
        if a is None:
            a = self._alpha[v] = alpha_stream(self.padded(self.view_pixels(v))[..., -1])
        return a

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

    def image_code(self, px: np.ndarray | None, planes: np.ndarray | None, sse: float, cnt: float) -> ViewCode:
        """The code of a view coded alone as an image (JPEG 2000): no tbs, no coded block; its
        decoded pixels and planes where kept, its colour squared error ``sse`` over ``cnt``."""
        return ViewCode(np.zeros(self.nby8 * self.nbx8, np.int8), np.zeros(0, np.int64),
                        np.zeros((0, self.P, 64), np.int16), np.zeros(self.nby * self.nbx, bool), px, planes,
                        0.0, sse, cnt)


__all__ = ["TxParams", "TxEncoder", "Model", "default_counts"]
