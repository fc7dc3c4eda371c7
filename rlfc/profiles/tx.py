"""Profile ``tx``: multi-reference disparity prediction from key views, transform-coded and
entropy-coded residuals with rate-distortion decisions (grids).

Key views lie on a coarser sub-grid; they are coded view by view (an intra view from its
thumbnail, the others predicted from key views coded before them) and decoded when the file
is opened. Every other view is predicted block by block from the key views around it (one
disparity and one prediction mode per 8×8 block and cell of views), plus, where the encoder
found it worth its bits, one stored stream per B×B block: 8×8 integer-DCT coefficients
(HEVC's matrix), rANS-coded with static per-file tables (:mod:`rlfc.txsyntax`). One block
request = the in-memory key views + at most one stored stream. The decoder's parts: what it
decodes on first need (maps, key-view block rows: :mod:`rlfc.profiles.tx_lazy`) and its lean
one-request paths (:mod:`rlfc.profiles.tx_single`) and its residual path: parsing,
dequantization, inverse transform (:mod:`rlfc.profiles.tx_residual`).

Levels: 0 = full quality; 1 = prediction only (key views stay full).
"""
from __future__ import annotations

import collections
import threading

import numpy as np

from formats.errors import FormatError, UnsupportedError
from formats.pixels import cv_saturating_depth, from_planes

from ..txlayout import MAX_REFS, TxLayout, weighted_views
from ..txwarp import offsets, pair_params, view_offsets
from ..txpredict import TB, mode_weights, planar, predict_tbs, weigh
from ..txmaps import LazyMaps
from ..txsections import stream_order, unpack_index, unpack_thumbs
from ..txsample import KeyAtlas, predict as remap_predict, predict_view
from ..txsyntax import plane_classes, tables_from_bytes, tables_from_quantized
from ..xp import NUMPY
from .base import Profile, ProfileDecoder
from .tx_lazy import OnDemand
from .tx_residual import Residuals
from .tx_single import SingleRequests

PAD = 8
PRED_TBS = 1024         # 8×8 blocks per prediction pass (temporaries stay in cache)
PARSE_TBS = 16384       # 8×8 blocks per parse (the rANS lanes of all their streams step together)
GROUP_PIXELS = 1 << 21  # pixels of the views decoded together by decode_views
SCRATCH_BYTES = 64 << 20   # the largest int32 planes a thread keeps for views() (GROUP_PIXELS' at 4 planes: 32 MiB)
SECTIONS = ("tx.layout", "tx.tables", "tx.maps", "tx.thumbs", "tx.keyimg", "tx.index", "tx.blocks")


def plane_limits(planes: int, peak: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(lo, hi, flat) per plane: the value range of YCoCg-R planes and the flat (intra)
    prediction: Y/grey/alpha in [0, peak] (flat = (peak + 1)/2), Co/Cg in [−peak, peak] (flat 0)."""
    pc = plane_classes(planes)
    lo = np.where(pc == 1, -peak, 0)
    hi = np.full(planes, peak)
    flat = np.where(pc == 1, 0, (peak + 1) // 2)
    return lo.astype(np.int64), hi.astype(np.int64), flat.astype(np.int64)




class TxDecoder(OnDemand, SingleRequests, Residuals, ProfileDecoder):
    """Planes decoder of a ``tx`` file (see :class:`rlfc.profiles.base.ProfileDecoder`)."""

    levels = 1
    threads_ok = True             # shared state: read-only after open; byte reads under a lock
    reads_checked = True          # streams, key images and rows are read through checked calls

    def __init__(self, container, header, cfg, limits=None):
        from formats.limits import DEFAULT

        limits = limits or DEFAULT
        c, name = container, container.name
        self.container, self.hdr = c, header
        B = self.block_size = header.block_size
        if B % TB:
            raise FormatError(f"{name}: tx blocks must be multiples of {TB} pixels, got {B}")
        self.Hp, self.Wp = header.padded
        self.nby, self.nbx = header.blocks
        self.P, self.dtype = header.planes, header.dtype
        self.n_views = N0 = header.n_views
        self.tpb = B // TB
        self.nt = self.tpb ** 2
        self.nby8, self.nbx8 = self.Hp // TB, self.Wp // TB
        lay = self.lay = TxLayout.read(cfg.sub("tx"), c.read("tx.layout"), N0, self.P, name)
        self.wmode = mode_weights(lay.weights)                   # (views, R + 1, R): weights per tb mode
        # views whose prediction is weighted (version 4; the lean one-request path weighs in floats)
        self._weighted = np.zeros(N0, bool) if lay.wp is None else weighted_views(lay.wp)
        keys = np.asarray(lay.keys, np.int64)
        if keys.size * self.Hp * self.Wp > limits.max_open_pixels:
            raise FormatError(f"{name}: {keys.size} key views of {self.Hp}x{self.Wp} exceed the open-time limit of "
                              f"{limits.max_open_pixels} pixels")
        for s in SECTIONS:
            c.info(s)
        self.pcs = plane_classes(self.P)
        self._pcl = self.pcs.tolist()                 # (the one-stream parser's form)
        peak = int(np.iinfo(self.dtype).max)
        self.lo, self.hi, self.flat = plane_limits(self.P, peak)
        self.lo_tb, self.hi_tb = (np.tile(x.astype(np.int32), TB * TB) for x in (self.lo, self.hi))   # an 8×8 tb's
        self.tables = tables_from_quantized(tables_from_bytes(c.read("tx.tables"), f"{name}: tx.tables"), lay.version)
        # maps are decoded when a request first needs them (lazy, as key rows: a first frame
        # reads a few of a grid's dozens); a map's modes may not select a reference one of its
        # views lacks
        nrefs = (lay.refs >= 0).sum(axis=1)
        users = np.flatnonzero(lay.cell >= 0)
        max_mode = np.full(lay.n_maps, MAX_REFS, np.int64)
        np.minimum.at(max_mode, lay.cell[users], nrefs[users])
        self._map_store = LazyMaps(c.read("tx.maps"), lay.n_maps, (self.nby8, self.nbx8), 1 + MAX_REFS,
                                   f"{name}: tx.maps", max_mode)
        self._map_done = np.zeros(lay.n_maps, bool)          # set once a map's key-view reach is known too
        self._map_lock = threading.Lock()
        intra = [int(k) for k in lay.coded_keys if lay.intra[k]]
        self.thumbs = unpack_thumbs(c.read("tx.thumbs"), (len(intra), self.nby8, self.nbx8, self.P),
                                    f"{name}: tx.thumbs")
        self.thumb_of = {k: i for i, k in enumerate(intra)}
        # a level is a rounded block mean over the step: larger products are no block mean (and
        # would overflow the int32 upsampling)
        if self.thumbs.size and int(np.abs(self.thumbs).max()) * lay.thumb_step16 > 16 * (peak + 1) + lay.thumb_step16:
            raise FormatError(f"{name}: tx.thumbs: a thumbnail level times the thumbnail step exceeds the sample range")
        nloc = self.nby * self.nbx
        is_key = np.zeros(N0, bool)
        is_key[keys] = True
        ck = lay.coded_keys
        self.key_split = ks = lay.key_split
        if self.nbx % ks:
            raise FormatError(f"{name}: config.tx.key_split {ks} does not divide the {self.nbx} blocks of a row")
        key_len, coded, lengths = unpack_index(c.read("tx.index"), len(ck), self.nby * ks, N0, nloc, is_key,
                                               f"{name}: tx.index")
        off = np.concatenate([[0], np.cumsum(np.concatenate([key_len.reshape(-1), lengths]))])
        nk = key_len.size
        self.row_of = {k: i for i, k in enumerate(ck)}
        self.key_start = off[:nk].reshape(len(ck), self.nby, ks)        # (coded key, row, segment)
        self.key_end = off[1:nk + 1].reshape(len(ck), self.nby, ks)
        img = lay.image_of                                    # JPEG 2000 intra keys, in key order
        img_keys = [k for k in lay.keys if k in img]
        img_off = np.concatenate([[0], np.cumsum([img[k] for k in img_keys])]).astype(np.int64)
        if c.info("tx.keyimg").length != img_off[-1]:
            raise FormatError(f"{name}: section 'tx.keyimg' has {c.info('tx.keyimg').length} bytes, the header "
                              f"says {img_off[-1]}")
        self.img_of = {k: (int(img_off[i]), int(img_off[i + 1])) for i, k in enumerate(img_keys)}
        self.alpha_of = lay.alpha_of                          # (version 6: bytes of alpha ending each entry)
        sv, sl = stream_order(coded)
        self.start = np.full((N0, nloc), -1, np.int64)
        self.end = np.full((N0, nloc), -1, np.int64)
        self.start[sv, sl], self.end[sv, sl] = off[nk:-1], off[nk + 1:]
        self.coded = coded
        self._io = threading.Lock()
        self._tby = np.repeat(np.arange(self.tpb), self.tpb)       # tbs of a block, raster order
        self._tbx = np.tile(np.arange(self.tpb), self.tpb)
        self._tb_off = self._tby * self.nbx8 + self._tbx           # their raster indices from the first
        self._row_planes = np.tile(np.arange(self.P), self.nt)     # the plane of each (tb, plane) row of a block
        self._q16_rows = np.asarray(lay.step16[1], np.int64)[self._row_planes]    # ... its step (non-key views)
        self._tb_y = (self._tby * TB).astype(np.float32)           # their pixel origins in the block
        self._tb_x = (self._tbx * TB).astype(np.float32)
        self._blockref_cache: dict = {}
        self._pixref_cache: dict = {}                           # view → block_pixel_refs (block_pixels)
        self._res_tab = None                                    # _residual_pixels' look-ups (_res_tables)
        self._warp_px_cache: dict = {}                          # view → _warp_pixels (warped files)
        self._cell_maps: dict = {}                              # map → (disparities as float32, modes)
        self._pix_ready: dict = {}     # view → (its _pixel_refs, its map's _cell_map), once nothing is left to decode
        self._peak = int(np.iinfo(self.dtype).max)
        if c.info("tx.blocks").length != off[-1] + PAD:
            raise FormatError(f"{name}: section 'tx.blocks' has {c.info('tx.blocks').length} bytes, the index "
                              f"says {off[-1] + PAD}")
        self._remote = c.is_remote
        self.buf = None if self._remote else c.array("tx.blocks", verify=False)
        self.key_slot = np.full(N0, -1, np.int64)
        self.key_slot[keys] = np.arange(keys.size)
        self.is_key = self.key_slot >= 0
        r0 = lay.refs.clip(0)                                  # per view: its references' key slots
        self.ref_slots = self.key_slot[r0].clip(0)              # (views, R) (any valid slot at weight 0)
        self.ref_dpos = lay.positions[:, None, :] - lay.positions[r0]     # (views, R, 2) position offsets
        # version 5: (views, R, 4) each (view, reference)'s warp difference (rlfc.txwarp), else None
        # (every prediction path adds their offsets; the lean single-block path from _warp_pixels)
        self.warp_dw = None if lay.warp is None or not lay.warp.any() else pair_params(lay.warp, lay.refs)
        self.keyplanes = np.zeros((keys.size, self.Hp, self.Wp, self.P), np.int32)
        self._kp = None
        # the float atlas the prediction samples: none where no view is predicted (a posed
        # capture, every view an intra key; it would hold a float copy of every decoded view)
        fits = KeyAtlas.fits(self.Hp, self.Wp, self.P) and not lay.intra.all()
        self.atlas = KeyAtlas(keys.size, self.Hp, self.Wp, self.P, KeyAtlas.sample_bits(self.dtype, self.P)) \
            if fits else None
        self._pixel_bounds = None          # the planes' (lo, hi) over the atlas's C channels, its float type (±inf
        if self.atlas is not None:         # past P): where block_pixels clips a coded block's sum
            ft, C = self.atlas.ftype, self.atlas.C
            lw, hg = np.full(C, -np.inf, ft), np.full(C, np.inf, ft)
            lw[:self.P], hg[:self.P] = self.lo, self.hi
            # tiled over a block's samples: the clip then runs on arrays of one shape (bounds of C
            # values broadcast along the last axis make numpy's inner loops C elements long)
            n = self.nt * TB * TB
            self._pixel_bounds = (np.tile(lw, (n, 1)), np.tile(hg, (n, 1)))
            self._peak_f = ft(self._peak)  # (block_pixels' clip bound, made once)
            self._pix_depth = cv_saturating_depth(self.dtype, self._peak)   # (and its clip + cast in OpenCV)
            # the atlas's channels that bypass the transform (None: none does), for _residual_pixels
            bp = np.concatenate([lay.bypass[:self.P], np.zeros(C - self.P, bool)])
            self._bypass_c = bp if bp.any() else None
        # key views are decoded by block rows when a request first needs them (lazy: opening a
        # file reads and decodes nothing of them; :meth:`decode_keys` decodes them all)
        self._key_done = np.zeros((keys.size, self.nby), bool)
        # views a whole-view decode takes straight from their JPEG 2000 codestream to pixels
        # (image_views): JPEG 2000 intra keys that no view is predicted from
        self._direct = np.zeros(N0, bool)
        self._direct[list(self.img_of)] = True
        self._direct[lay.refs[lay.refs >= 0]] = False
        self._img_cache: collections.OrderedDict = collections.OrderedDict()   # (image_pixels)
        self._img_bytes, self._img_lock = 0, threading.Lock()
        self._rows_ok = np.zeros((N0, self.nby), bool)            # (view, block row): its key rows are decoded
        self._keys_all = keys.size == 0
        self._key_lock = threading.RLock()
        self._in_keys = threading.local()              # .active: this thread is decoding key rows
        self._scratch = threading.local()              # .planes: this thread's buffer for views()
        self._thumb_up: dict = {}
        self._reach = np.zeros((N0, self.nby), np.int64)       # rows filled as their maps are decoded

    # -- streams ----------------------------------------------------------------------------
    def _streams(self, starts: np.ndarray, ends: np.ndarray):
        """(buffer, starts, ends) holding the given streams of ``tx.blocks``, checksums verified
        for the bytes read (a byte-range source fetches only these ranges, merged)."""
        with self._io:
            return self._streams_locked(starts, ends)

    def _streams_locked(self, starts: np.ndarray, ends: np.ndarray):
        c = self.container
        if not self._remote:
            if starts.size:
                c.verify_ranges("tx.blocks", starts, ends)
            return self.buf, starts, ends
        order = np.argsort(starts)
        parts, new_start = [], np.empty_like(starts)
        pos = 0
        a = b = None
        runs = []
        for i in order.tolist():                              # merge touching ranges
            s, e = int(starts[i]), int(ends[i])
            if a is not None and s <= b:
                b = max(b, e)
            else:
                if a is not None:
                    runs.append((a, b))
                a, b = s, e
        if a is not None:
            runs.append((a, b))
        if len(runs) > 1:                                     # (their missing chunks in as few requests as
            c.fetch_ranges("tx.blocks", [r[0] for r in runs], [r[1] for r in runs])   # there are runs of them)
        run_pos = {}
        for a, b in runs:
            parts.append(np.frombuffer(c.read("tx.blocks", a, b), np.uint8))
            run_pos[a] = pos
            pos += b - a
        ra = np.array([r[0] for r in runs], np.int64)
        for i in range(starts.size):
            j = int(np.searchsorted(ra, starts[i], side="right")) - 1
            new_start[i] = run_pos[int(ra[j])] + starts[i] - ra[j]
        buf = np.concatenate(parts + [np.zeros(PAD, np.uint8)]) if parts else np.zeros(PAD, np.uint8)
        return buf, new_start, new_start + (ends - starts)

    # -- prediction ---------------------------------------------------------------------------
    @property
    def kp(self) -> np.ndarray:
        """(P, n_keys·Hp·Wp) planar key views (the gather layout of ``predict_tbs``), built on
        first use. While this thread decodes key rows (a predicted key view, without the remap
        atlas: views too large for OpenCV), the rows decoded so far, uncached: the rows a key
        samples are decoded before it."""
        if getattr(self._in_keys, "active", False):
            return planar(self.keyplanes)
        self.decode_keys()
        if self._kp is None:
            self._kp = planar(self.keyplanes)
        return self._kp

    def pred_tables(self, views=None):
        """The tables :func:`pred_inputs` reads: (cell (views,), disp and modes (maps, 8×8 blocks),
        wmode (views, R + 1, R), ref_slots (views, R), ref_dpos (views, R, 2)), plus the warp
        differences (views, R, 4) of a warped file (version 5), numpy; with ``views``, only their
        maps are sure to be decoded."""
        disp, modes = self._maps_of(views)
        t = (self.lay.cell, disp, modes, self.wmode, self.ref_slots, self.ref_dpos)
        return t if self.warp_dw is None else t + (self.warp_dw,)

    def _pred(self, views, ty, tx):
        """(M, 8, 8, P) prediction of 8×8 blocks (ty, tx) of views with references (weighted
        where the file says so)."""
        args = pred_inputs(self.pred_tables(views), self.nbx8, views, ty, tx)
        if self.atlas is not None:
            p = remap_predict(self.atlas, *args)
        else:
            p = predict_tbs(NUMPY, self.kp, (self.Hp, self.Wp), *args)
        return self._weigh(p, views)

    def _weigh(self, pred, views):
        """``pred`` (M, …, P) int32 of views ``views`` (M,) (or one view, an int) with each view's
        weighted prediction applied (files of version 4; else as it is): in place where ``pred``
        is C-contiguous int32, else on a copy; the result is returned."""
        wp = self.lay.wp
        if wp is None:
            return pred
        if np.ndim(views) == 0:
            if not self._weighted[views]:
                return pred
            return weigh(pred, wp[views, :, 0], wp[views, :, 1], self.lo, self.hi)
        # only the rows of weighted views (a file weighs some views: the others' rows are left
        # alone rather than weighed by the identity, five passes over every predicted sample)
        w = self._weighted[views]
        if not w.any():
            return pred
        if w.all():
            sel = wp[views]                # (M, P, 2): one row of 64·P samples per 8×8 block
            return weigh(pred, sel[..., 0], sel[..., 1], self.lo, self.hi)
        rows = np.flatnonzero(w)
        sel = wp[np.asarray(views)[rows]]
        if not pred.flags.c_contiguous or pred.dtype != np.int32:
            pred = np.ascontiguousarray(pred, np.int32)
        pred[rows] = weigh(pred[rows], sel[..., 0], sel[..., 1], self.lo, self.hi)
        return pred

    def _tb_coords(self, views, locs, xp=NUMPY):
        """(views, ty, tx) of every 8×8 block of blocks ``locs`` (flat) of ``views``, block by
        block in raster order within each; numpy, or the tensors of ``xp``."""
        by, bx = locs // self.nbx, locs % self.nbx
        t = xp.arange(self.nt)
        ty = (by[:, None] * self.tpb + t // self.tpb).reshape(-1)
        tx = (bx[:, None] * self.tpb + t % self.tpb).reshape(-1)
        return xp.repeat(views, self.nt), ty, tx

    def _reconstruct(self, views, locs, level, pred=None, parsed=None, have=None, pixels=None):
        """(M, B, B, P) int32 planes of block requests (views with references, or ``pred`` given
        as (M, nt, 8, 8, P)); ``parsed``: the syntax of the requests ``have`` (default: of every
        request, key rows), else the coded requests' own streams are parsed (all at once: the
        rANS lanes step together). ``pixels``: a dtype, then their pixels of that dtype."""
        M, B, nt, P = views.size, self.block_size, self.nt, self.P
        if pred is None:
            pred = np.empty((M, nt, TB, TB, P), np.int32)
            step = max(1, PRED_TBS // nt)                     # requests per prediction pass: stays in cache
            for a in range(0, M, step):
                v, lc = views[a:a + step], locs[a:a + step]
                pred[a:a + step] = self._pred(*self._tb_coords(v, lc)).reshape(v.size, nt, TB, TB, P)
        out = pred if pred.dtype == np.int32 else pred.astype(np.int32)
        if level == 0:
            if have is None:
                have = np.arange(M) if parsed is not None else np.flatnonzero(self.coded[views, locs])
            if have.size:
                if parsed is None:
                    parsed = self._parse(views[have], locs[have])
                res = self._residual(views[have], parsed)
                if have.size == M:                    # every request coded (key rows): no gather, no scatter
                    out = self._add_residual(out, res, parsed.modes)
                else:
                    out[have] = self._add_residual(out[have], res, parsed.modes)
        if pixels is not None:                        # (per sample: the tbs' layout does not matter)
            out = from_planes(out, pixels)
        # tbs → blocks: (M, tpb, tpb, 8, 8, P) → (M, B, B, P)
        return out.reshape(M, self.tpb, self.tpb, TB, TB, P).transpose(0, 1, 3, 2, 4, 5).reshape(M, B, B, P)

    def _view_planes(self, v: int, level: int, parsed=None, out=None) -> np.ndarray:
        """(Hp, Wp, P) int32 planes of a view with references: its 8×8 blocks predicted in
        raster order, the coded blocks' residuals added where they lie (``parsed``: their
        syntax, when the caller parsed several views together; ``out``: where to write them,
        a C-contiguous int32 array of that shape)."""
        n8y, n8x, tpb, P = self.nby8, self.nbx8, self.tpb, self.P
        T = n8y * n8x
        if self.atlas is None:
            ty, tx = np.divmod(np.arange(T), n8x)
            pred = np.empty((T, TB, TB, P), np.int32)
            vv = np.full(min(T, PRED_TBS), v)
            for a in range(0, T, PRED_TBS):
                b = min(T, a + PRED_TBS)
                pred[a:b] = self._pred(vv[:b - a], ty[a:b], tx[a:b])
            planes = pred.reshape(n8y, n8x, TB, TB, P).transpose(0, 2, 1, 3, 4).reshape(self.Hp, self.Wp, P)
            if out is None:
                out = planes
            else:
                out[...] = planes
        else:                           # raster bands of blend (mode 0) blocks, then the other blocks
            out = self._raster_prediction(v, out)
        locs = np.flatnonzero(self.coded[v]) if level == 0 else np.zeros(0, np.int64)
        if locs.size:
            by, bx = np.divmod(locs, self.nbx)
            t = np.arange(self.nt)
            ty = (by[:, None] * tpb + t // tpb).reshape(-1)                                # (S·nt,) tb rows, cols
            tx = (bx[:, None] * tpb + t % tpb).reshape(-1)
            vs = np.full(locs.size, v)
            if parsed is None:
                parsed = self._parse(vs, locs)
            o4 = out.reshape(n8y, TB, n8x, TB, P)
            got = o4[ty, :, tx].reshape(locs.size, self.nt, TB, TB, P)
            o4[ty, :, tx] = self._add_residual(got, self._residual(vs, parsed), parsed.modes).reshape(-1, TB, TB, P)
        return out

    def _raster_prediction(self, v: int, out=None, rows: tuple[int, int] | None = None) -> np.ndarray:
        """(8·n, Wp, P) int32 weighted prediction of view v (with references; the atlas) in raster
        bands (:func:`rlfc.txsample.predict_view`): the whole view, or its 8×8 block rows
        ``rows`` = (a, b) (n = b − a); written to ``out`` where given (C-contiguous int32)."""
        slots, wmode, dpos = self._view_refs(v)
        cell = self.lay.cell[v]
        disp, modes = self._maps_of([v])
        warp = None if self.warp_dw is None else view_offsets(self.warp_dw[v], self.nby8, self.nbx8)
        out = predict_view(self.atlas, slots, wmode[0], disp[cell], modes[cell], dpos, self.nby8, self.nbx8,
                           out=out, warp=warp, rows=rows)
        self._weigh(out, v)                       # (in place: ``out`` is C-contiguous int32)
        return out

    def _key_rows_planes(self, k: int, rr: np.ndarray, parsed) -> np.ndarray:
        """(n, B, Wp, P) int32 planes of block rows ``rr`` (n,) ascending of key view k, which
        has references (every block of a key row is coded: ``parsed`` holds their syntax, the
        rows' blocks in order): each run of consecutive rows predicted in raster bands
        (:func:`rlfc.txsample.predict_view`), then the residuals added tb by tb; the integers of
        :meth:`_reconstruct`'s block by block prediction (a quarter to a third of a first frame's
        key rows on the grids whose keys are predicted: BENCHMARKS.md)."""
        B, tpb, P, nbx, n = self.block_size, self.tpb, self.P, self.nbx, rr.size
        out = np.empty((n * B, self.Wp, P), np.int32)
        cut = (np.flatnonzero(np.diff(rr) != 1) + 1).tolist()
        for lo, hi in zip([0] + cut, cut + [n]):
            self._raster_prediction(k, out[lo * B:hi * B], (int(rr[lo]) * tpb, (int(rr[hi - 1]) + 1) * tpb))
        # (rows, tb row, y, blocks, tb column, x, P) → (rows · blocks, tbs, 8, 8, P) and back
        tbs = out.reshape(n, tpb, TB, nbx, tpb, TB, P).transpose(0, 3, 1, 4, 2, 5, 6).reshape(n * nbx, self.nt, TB,
                                                                                            TB, P)
        tbs = self._add_residual(tbs, self._residual(np.full(n * nbx, k), parsed), parsed.modes)
        return tbs.reshape(n, nbx, tpb, tpb, TB, TB, P).transpose(0, 2, 4, 1, 3, 5, 6).reshape(n, B, self.Wp, P)

    def _key_image(self, k: int, threads: int) -> np.ndarray:
        """(Hp, Wp, C) pixels of JPEG 2000 intra key view ``k``, decoded on ``threads`` of
        OpenJPEG's threads (its bytes read under the I/O lock: a byte-range source is shared)."""
        from ..topcodec import decode_image, decode_view_j2k

        a, b = self.img_of[k]
        with self._io:
            data = bytes(self.container.read("tx.keyimg", a, b))
        if k in self.alpha_of:                                # colour codestream, then the alpha stream
            return decode_view_j2k(data, (self.Hp, self.Wp, self.P), self.dtype, self.alpha_of[k], threads,
                                   what=f"{self.container.name}: view {k}")
        return decode_image("j2k", data, (self.Hp, self.Wp, self.P), self.dtype, threads=threads)

    def _set_key_image(self, k: int, img: np.ndarray) -> None:
        """Store the pixels of JPEG 2000 intra key view ``k`` (all its rows)."""
        from formats.pixels import to_planes

        B = self.block_size
        self._set_key_rows(int(self.key_slot[k]), np.arange(self.nby),
                           to_planes(img).reshape(self.nby, B, self.Wp, self.P))

    # -- ProfileDecoder ---------------------------------------------------------------------
    def _key_blocks(self, views, by, bx):
        """(M, B, B, P) blocks of key views, one flat take of pixel rows (2x faster than indexing
        the (keys, Hp, Wp, P) planes with three broadcast index arrays, measured)."""
        B = self.block_size
        first = (self.key_slot[views] * self.Hp + by * B) * self.Wp + bx * B           # (M,) top-left pixel
        idx = (first[:, None] + np.arange(B) * self.Wp)[:, :, None] + np.arange(B)     # (M, B, B)
        return self.keyplanes.reshape(-1, self.P).take(idx.reshape(-1), axis=0).reshape(views.size, B, B, self.P)

    #: :meth:`blocks` gives pixels where asked (``pixels=dtype``)
    blocks_to_pixels = True

    def blocks(self, views, by, bx, level, ahead=None, first: int = 0, pixels=None):
        """(M, B·B, P) int32 planes of requests; ``ahead``: :meth:`preparse` of the call whose
        requests ``first``, ``first`` + 1, … these are. ``pixels`` (uint8 or uint16): the
        requests' pixels instead (:func:`formats.pixels.from_planes` of those planes), made
        before the 8×8 blocks are put together into blocks, so that those copies move the
        pixels, not the int32 planes (a quarter of the bytes for 8-bit samples)."""
        out = np.empty((views.size, self.block_size, self.block_size, self.P), np.int32 if pixels is None else pixels)
        if not self._keys_all:                       # every key-view row the call reads, in one pass
            self._have_rows(views, by)
        key = self.is_key[views]
        if key.any():
            kb = self._key_blocks(views[key], by[key], bx[key])
            out[key] = kb if pixels is None else from_planes(kb, pixels)
        nk = np.flatnonzero(~key)
        if nk.size:
            order = nk[np.lexsort((bx[nk], by[nk], views[nk]))]          # by view, then raster: shared
            step = max(1, PARSE_TBS // self.nt)                         # references stay in cache
            for a in range(0, order.size, step):
                c = order[a:a + step]
                parsed = have = None
                if ahead is not None:               # the chunk's streams, parsed with others'
                    have, parsed = ahead.chunk(first + c)
                out[c] = self._reconstruct(views[c], by[c] * self.nbx + bx[c], level, parsed=parsed, have=have,
                                           pixels=pixels)
        B = self.block_size
        return out.reshape(views.size, B * B, self.P)

    def views(self, views, level):
        """Whole views; the coded blocks of all of them parsed together (the rANS lanes step
        together: one parse costs about the longest stream, so many views share it)."""
        out = self._planes_scratch((views.size, self.Hp, self.Wp, self.P))
        if not self._keys_all:
            self._have_keys(self._need_views(views))
        pv = [int(v) for v in views.tolist() if not self.is_key[v]]
        parsed = {}
        if level == 0 and len(pv) > 1:
            locs = [np.flatnonzero(self.coded[v]) for v in pv]
            n = np.array([x.size for x in locs])
            if n.sum():
                got = self._parse(np.repeat(pv, n), np.concatenate(locs))
                parsed = dict(zip(pv, got.split(np.concatenate([[0], np.cumsum(n)]))))
        for i, v in enumerate(views.tolist()):
            if self.is_key[v]:
                out[i] = self.keyplanes[self.key_slot[v]]
                continue
            self._view_planes(v, level, parsed.get(v), out=out[i])
        return out

    def _planes_scratch(self, shape: tuple) -> np.ndarray:
        """An int32 array of ``shape`` for :meth:`views`' planes: this thread's buffer, kept from
        call to call (up to SCRATCH_BYTES), so that decoding view after view writes to pages
        already mapped (a fresh 512×512 view's planes are 768 pages, each faulted in on its first
        write where malloc has given the memory back: BENCHMARKS.md). Valid until this thread's
        next call."""
        n = int(np.prod(shape))
        if 4 * n > SCRATCH_BYTES:
            return np.empty(shape, np.int32)
        buf = getattr(self._scratch, "planes", None)
        if buf is None or buf.size < n:
            buf = self._scratch.planes = np.empty(n, np.int32)
        return buf[:n].reshape(shape)

    def prepare(self, views, by):
        if not self._keys_all:
            self._have_rows(views, by)

    def view_groups(self, views: np.ndarray) -> list:
        """Views in groups whose coded blocks are parsed together (about PARSE_TBS tbs, at most
        GROUP_PIXELS pixels each: the group's int32 planes are held at once); the key-view rows
        every group reads are decoded first, in one pass."""
        if not self._keys_all:
            self._have_keys(self._need_views(views))
        cost = self.coded[views].sum(axis=1) * self.nt + 1
        most = max(1, GROUP_PIXELS // (self.Hp * self.Wp))
        groups, cur, acc = [], [], 0
        for v, c in zip(views.tolist(), cost.tolist()):
            if cur and (acc + c > PARSE_TBS or len(cur) >= most):
                groups.append(np.array(cur))
                cur, acc = [], 0
            cur.append(v)
            acc += c
        if cur:
            groups.append(np.array(cur))
        return groups

    def torch(self, device):
        from .tx_torch import TorchTx

        return TorchTx(self, device)

    def info(self) -> dict:
        lay = self.lay
        return {"key_views": len(lay.keys), "maps": lay.n_maps, "coded_blocks": int(self.coded.sum()),
                "blocks_per_view": self.nby * self.nbx, "key_row_streams": self.key_split,
                "layout_version": int(lay.version), "weighted_views": int(self._weighted.sum()),
                "warped_views": 0 if lay.warp is None else int(lay.warp.any(axis=1).sum()),
                "jpeg2000_views": len(self.img_of), "alpha_stream_bytes": int(sum(self.alpha_of.values()))}


def pred_inputs(tables, nbx8: int, views, ty, tx):
    """The arguments (slots, weights, disp_y, disp_x, y0, x0) of
    :func:`rlfc.txpredict.predict_tbs` for 8×8 blocks (ty, tx) of ``views`` (M,), from
    :meth:`TxDecoder.pred_tables` (numpy arrays, or their copies on a torch device with torch
    requests): each block's map cell, disparity and mode, its view's reference slots, the mode's
    weights, and the displacements (disparity × position offset, plus the warps' offsets in a
    version 5 file; 1/16 pixel)."""
    cell_of, disp, modes, wmode, ref_slots, ref_dpos = tables[:6]
    cell = cell_of[views]
    loc8 = ty * nbx8 + tx
    d = disp[cell, loc8][:, None]
    dpos = ref_dpos[views]                                                          # (M, R, 2)
    dy, dx = d * dpos[..., 0], d * dpos[..., 1]
    if len(tables) > 6:                                  # per-view warps: each (block, reference)'s offset
        oy, ox = offsets(tables[6][views], ty, tx)
        dy, dx = dy + oy, dx + ox
    return ref_slots[views], wmode[views, modes[cell, loc8]], dy, dx, ty * TB, tx * TB


class TxProfile(Profile):
    id = "tx"
    description = ("multi-reference disparity prediction from key views, transform-coded rANS residuals with "
                   "rate-distortion decisions (grids); posed captures: every view coded on its own")

    def accepts(self, lf):
        return None

    def encode(self, lf, options, progress=None):
        why = self.accepts(lf)
        if why:
            raise UnsupportedError(f"{why}; use --profile bise")
        from ..txrate import encode_tx

        return encode_tx(lf, options, progress)

    def open(self, container, header, cfg, limits=None):
        return TxDecoder(container, header, cfg, limits)


PROFILE = TxProfile()
