"""Profile ``tx``: multi-reference disparity prediction from key views, transform-coded and
entropy-coded residuals with rate-distortion decisions (grids).

Key views lie on a coarser sub-grid; they are coded view by view (an intra view from its
thumbnail, the others predicted from key views coded before them) and decoded when the file
is opened. Every other view is predicted block by block from the key views around it (one
disparity and one prediction mode per 8×8 block and cell of views), plus, where the encoder
found it worth its bits, one stored stream per B×B block: 8×8 integer-DCT coefficients
(HEVC's matrix), rANS-coded with static per-file tables (:mod:`rlfc.txsyntax`). One block
request = the in-memory key views + at most one stored stream.

Levels: 0 = full quality; 1 = prediction only (key views stay full).
"""
from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from formats.errors import FormatError, UnsupportedError
from formats.parallel import LOCAL_THREADS
from formats.pixels import from_planes

from ..kernels import dequantize
from ..transform import COEF_MAX, ZIGZAG, inverse_float
from ..txlayout import MAX_REFS, TxLayout, weighted_views
from ..txwarp import max_row_offset, offsets, pair_params, view_offsets
from ..txpredict import DISP_BITS, TB, mode_weights, planar, predict_tbs, upsample_thumb, weigh
from ..txmaps import LazyMaps
from ..txsections import stream_order, unpack_index, unpack_thumbs
from ..txsample import (KeyAtlas, block_pixel_refs, block_refs, predict as remap_predict, predict_block,
                        predict_block_pixels, predict_view)
from ..txparse import concat_parsed, parse_lanes, parse_one
from ..txsyntax import MODE_INTRA, plane_classes, tables_from_bytes, tables_from_quantized
from ..xp import NUMPY
from .base import Profile, ProfileDecoder


def _dequantize_clipped(values, q16) -> np.ndarray:
    """:func:`rlfc.kernels.dequantize` of levels ``values`` at steps ``q16`` (1/16; numpy), clipped
    to ±COEF_MAX."""
    deq = dequantize(NUMPY, values, q16)
    return np.minimum(np.maximum(deq, -COEF_MAX, out=deq), COEF_MAX, out=deq)

PAD = 8
PRED_TBS = 1024         # 8×8 blocks per prediction pass (temporaries stay in cache)
PARSE_TBS = 16384       # 8×8 blocks per parse (the rANS lanes of all their streams step together)
#: a batched call's coded requests are parsed ahead of its chunks (:meth:`TxDecoder.preparse`)
#: in parses of this many streams, where it has at least PREPARSE_MIN: on epfl_iso_chart_1's
#: 10 862 streams of 20 000 random requests, 1 024 / 2 048 / 4 096 streams a parse took 178 /
#: 141 / 124 ms (a parse's temporaries: 16 / 29 / 62 MB)
PREPARSE_LANES = 4096
PREPARSE_MIN = 1024
#: streams are parsed one by one (plain Python, ~1.5 µs per byte) rather than as numpy lanes
#: stepping together (~85 µs per byte of the longest stream, whatever the number of lanes) while
#: their bytes sum to less than this many times the longest one's (measured on the dense grids'
#: key rows: one key's 19-27 rows parse 3-9× faster one by one)
ONE_BY_ONE_RATIO = 48
GROUP_PIXELS = 1 << 21  # pixels of the views decoded together by decode_views
SCRATCH_BYTES = 64 << 20   # the largest int32 planes a thread keeps for views() (GROUP_PIXELS' at 4 planes: 32 MiB)
KEY_PARSE_TBS = 1 << 20  # tbs of key-view rows parsed together (bounds the parsed coefficients held)
SECTIONS = ("tx.layout", "tx.tables", "tx.maps", "tx.thumbs", "tx.keyimg", "tx.index", "tx.blocks")


def plane_limits(planes: int, peak: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(lo, hi, flat) per plane: the value range of YCoCg-R planes and the flat (intra)
    prediction: Y/grey/alpha in [0, peak] (flat = (peak + 1)/2), Co/Cg in [−peak, peak] (flat 0)."""
    pc = plane_classes(planes)
    lo = np.where(pc == 1, -peak, 0)
    hi = np.full(planes, peak)
    flat = np.where(pc == 1, 0, (peak + 1) // 2)
    return lo.astype(np.int64), hi.astype(np.int64), flat.astype(np.int64)


#: views whose warp offsets the lean single-block path keeps (:meth:`TxDecoder._warp_pixels`;
#: 128 KiB a view of 512² pixels)
WARP_PX_VIEWS = 64


class TxDecoder(ProfileDecoder):
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
        self._res_tab = None                                    # _residual_rows' look-ups (_res_tables)
        self._warp_px_cache: dict = {}                          # view → _warp_pixels (warped files)
        self._cell_maps: dict = {}                              # map → (disparities as float32, modes)
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
        fits = KeyAtlas.fits(self.Hp, self.Wp, self.P)
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
        # key views are decoded by block rows when a request first needs them (lazy: opening a
        # file reads and decodes nothing of them; :meth:`decode_keys` decodes them all)
        self._key_done = np.zeros((keys.size, self.nby), bool)
        self._rows_ok = np.zeros((N0, self.nby), bool)            # (view, block row): its key rows are decoded
        self._keys_all = keys.size == 0
        self._key_lock = threading.RLock()
        self._in_keys = threading.local()              # .active: this thread is decoding key rows
        self._scratch = threading.local()              # .planes: this thread's buffer for views()
        self._thumb_up: dict = {}
        self._reach = np.zeros((N0, self.nby), np.int64)       # rows filled as their maps are decoded

    # -- maps, on demand ------------------------------------------------------------------------
    @property
    def disp(self) -> np.ndarray:
        """(n_maps, nby8·nbx8) int64 disparities (1/16 px per view step), every map decoded."""
        return self._maps_of(None)[0]

    @property
    def modes(self) -> np.ndarray:
        """(n_maps, nby8·nbx8) int64 prediction modes, every map decoded."""
        return self._maps_of(None)[1]

    def view_map(self, view: int) -> np.ndarray:
        """(nby8, nbx8) int64 disparity map (1/16 px per view step, one value per 8×8 block) that
        predicts view ``view`` (decoded now if not yet); ``view`` must have one (``lay.cell >= 0``)."""
        cell = int(self.lay.cell[view])
        if cell < 0:
            raise ValueError(f"view {view} is not predicted through a map")
        return self._maps_of([view])[0][cell].reshape(self.nby8, self.nbx8)

    def _maps_of(self, views) -> tuple[np.ndarray, np.ndarray]:
        """(disp, modes) (n_maps, nby8·nbx8) int64 with the maps of ``views`` (ints; None: every
        view) decoded; the other maps' rows may be zeros."""
        if views is None:
            if not self._map_done.all():
                self._have_maps(np.arange(self._map_done.size))
        else:
            cell = self.lay.cell[views]
            if not self._map_done[cell[cell >= 0]].all():
                self._have_maps(cell[cell >= 0])
        return self._map_store.disp, self._map_store.modes

    def _have_maps(self, cells: np.ndarray) -> None:
        """Decode maps ``cells`` where not done yet, and the key-view reach of their views' block
        rows (:meth:`_reach_rows`)."""
        with self._map_lock:
            new = self._map_store.need(cells)
            if new:
                self._reach_rows(np.asarray(new, np.int64))
                self._map_done[new] = True          # (threads read these flags without the lock)

    def _reach_rows(self, maps: np.ndarray) -> None:
        """Fill ``_reach`` (N0, nby) int64 for the views of ``maps``: how far (pixels, up or
        down) the prediction of a block row of each view with references samples its key views:
        ⌈max |disparity·Δrow| / 16⌉ + 1 (bilinear's second tap) over the block row's 8×8 blocks
        and the view's references; 0 for views without references."""
        lay = self.lay
        users = np.flatnonzero(np.isin(lay.cell, maps))
        if users.size == 0:
            return
        dmax = np.zeros((self._map_done.size, self.nby), np.int64)                            # (n_maps, nby)
        dmax[maps] = np.abs(self._map_store.disp[maps]).reshape(maps.size, self.nby, self.tpb * self.nbx8).max(axis=2)
        refs = lay.refs[users]
        dy = np.abs(lay.positions[users][:, None, 0] - lay.positions[refs.clip(0), 0])
        dy = np.where(refs >= 0, dy, 0).max(axis=1)                                            # (U,)
        self._reach[users] = -(-(dmax[lay.cell[users]] * dy[:, None]) // (1 << DISP_BITS)) + 1
        if self.warp_dw is not None:          # (plus the warps' largest vertical offset: one more pixel
            self._reach[users] += max_row_offset(self.warp_dw[users], self.Hp, self.Wp)[:, None] + 1   # for its rounding)

    # -- key views, by block rows, on demand ------------------------------------------------------
    def _row_span(self, views: np.ndarray, by: np.ndarray):
        """(lo, hi) block rows of the key views that block rows ``by`` of views with references
        sample (inclusive, clipped to the view)."""
        B = self.block_size
        self._maps_of(views)
        r = self._reach[views, by]
        return np.maximum(by * B - r, 0) // B, np.minimum((by + 1) * B - 1 + r, self.Hp - 1) // B

    def _spans(self, slots: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """(n_keys, nby) bool: block rows lo..hi (inclusive) of key slots ``slots`` (all (n,))."""
        nk, nby = self._key_done.shape
        diff = np.zeros((nk, nby + 1), np.int64)
        np.add.at(diff, (slots, lo), 1)
        np.add.at(diff, (slots, hi + 1), -1)
        return np.cumsum(diff[:, :nby], axis=1) > 0

    def _need_mask(self, views: np.ndarray, by: np.ndarray) -> np.ndarray:
        """(n_keys, nby) bool: the key-view block rows that requests (views, block rows) read:
        a key view its own row, any other view its references' rows around it."""
        key = self.is_key[views]
        v, b = views[~key], by[~key]
        refs = self.lay.refs[v]                                                  # (M, 4)
        lo, hi = self._row_span(v, b)
        has = refs >= 0
        return self._spans(np.concatenate([self.key_slot[views[key]], self.key_slot[refs.clip(0)][has]]),
                           np.concatenate([by[key], np.broadcast_to(lo[:, None], refs.shape)[has]]),
                           np.concatenate([by[key], np.broadcast_to(hi[:, None], refs.shape)[has]]))

    def _need_views(self, views: np.ndarray) -> np.ndarray:
        """(n_keys, nby) bool: every block row of the key views that whole ``views`` read."""
        need = np.zeros(self._key_done.shape, bool)
        for v in np.unique(views).tolist():
            if self.is_key[v]:
                need[self.key_slot[v]] = True
            else:
                r = self.lay.refs[v]
                need[self.key_slot[r[r >= 0]]] = True
        return need

    def _have_rows(self, views: np.ndarray, by: np.ndarray) -> None:
        """Decode the key-view rows that requests (views, block rows) read, where not done yet."""
        ok = self._rows_ok[views, by]
        if not ok.all():
            self._have_keys(self._need_mask(views[~ok], by[~ok]))
            self._rows_ok[views, by] = True

    def _have_keys(self, need: np.ndarray) -> None:
        """Decode the key-view block rows of ``need`` (n_keys, nby) that are not decoded yet."""
        if self._keys_all or not (need & ~self._key_done).any():
            return
        with self._key_lock:
            self._decode_key_rows(need)

    def decode_keys(self) -> None:
        """Decode every key view now (what opening a file did before key views were decoded on
        demand; the torch path and whole-view decodes of every view need them all)."""
        if not self._keys_all:
            self._have_keys(np.ones(self._key_done.shape, bool))

    def decode_maps(self) -> None:
        """Decode every map now (:meth:`_maps_of` of every view), with what a single request of
        each view reads from it (:meth:`_pixel_refs`, :meth:`_cell_map`)."""
        self._maps_of(None)
        if self.atlas is not None:
            for v in np.flatnonzero(~self.is_key & (self.lay.cell >= 0)).tolist():
                if self._pixel_refs(v) is not None:
                    self._cell_map(int(self.lay.cell[v]))

    def _decode_key_rows(self, need: np.ndarray) -> None:
        """Under the key lock: ``need``'s missing rows and the rows of other keys they are
        predicted from, keys in coding order (a key is predicted from keys before it). Block rows
        of transform-coded keys are parsed together (:meth:`_parse_streams`), in groups of about
        KEY_PARSE_TBS tbs (whole keys)."""
        self._in_keys.active = True
        try:
            self._decode_key_rows_now(need)
        finally:
            self._in_keys.active = False

    def _decode_key_rows_now(self, need: np.ndarray) -> None:
        lay = self.lay
        keys = [int(k) for k in lay.keys]
        need = need & ~self._key_done
        for s in range(len(keys) - 1, -1, -1):          # rows of the references a needed row samples
            k = keys[s]
            if not need[s].any():
                continue
            if k in self.img_of:                         # JPEG 2000: the whole view at once
                need[s] = ~self._key_done[s]
                continue
            if lay.intra[k]:
                continue
            rr = np.flatnonzero(need[s])
            lo, hi = self._row_span(np.full(rr.size, k), rr)
            refs = lay.refs[k]
            t = self.key_slot[refs[refs >= 0]]
            need |= self._spans(np.repeat(t, rr.size), np.tile(lo, t.size), np.tile(hi, t.size)) & ~self._key_done
        pending = [s for s in range(len(keys)) if keys[s] not in self.img_of and need[s].any()]
        group = max(1, KEY_PARSE_TBS // (self.nbx * self.nt))       # block rows per parse
        parsed: dict = {}
        pos = 0

        def parse_next():                                  # the next keys' rows, about a group
            nonlocal pos
            chunk, n = [], 0
            while pos < len(pending) and (not chunk or n + int(need[pending[pos]].sum()) <= group):
                t = pending[pos]
                chunk += [(t, r) for r in np.flatnonzero(need[t]).tolist()]
                n += int(need[t].sum())
                pos += 1
            parsed.update(self._parse_key_rows(chunk))

        images = [keys[s] for s in range(len(keys)) if keys[s] in self.img_of and need[s].any()]
        # JPEG 2000 keys decode on a thread of their own (OpenJPEG releases the GIL) while the
        # first group of transform-coded rows is parsed: a first frame waits for both
        pool = ThreadPoolExecutor(1) if images and pending else None
        try:
            got = {k: pool.submit(self._key_image, k, 1) for k in images} if pool else {}
            if pool:
                parse_next()
            self._key_rows_in_order(keys, need, parsed, parse_next, got)
        finally:
            if pool:
                pool.shutdown()
        if self._key_done.all():
            self._keys_all = True
            self._thumb_up.clear()

    def _key_rows_in_order(self, keys, need, parsed, parse_next, got) -> None:
        """:meth:`_decode_key_rows_now`'s rows ``need``, key by key in coding order: JPEG 2000
        keys from ``got`` (futures) or decoded now, the others reconstructed from ``parsed``
        (filled by ``parse_next``)."""
        lay, B, nby = self.lay, self.block_size, self.nby
        for s in range(len(keys)):
            rr = np.flatnonzero(need[s])
            if rr.size == 0:
                continue
            k = keys[s]
            if k in self.img_of:
                self._set_key_image(k, got[k].result() if k in got else self._key_image(k, LOCAL_THREADS))
                continue
            if s not in parsed:
                parse_next()
            p = parsed.pop(s)
            locs = (rr[:, None] * self.nbx + np.arange(self.nbx)).reshape(-1)
            pred = None
            if lay.intra[k]:
                up = self._thumb_up.get(k)
                if up is None:
                    th = (self.thumbs[self.thumb_of[k]] * lay.thumb_step16 + 8) >> 4
                    up = self._thumb_up[k] = upsample_thumb(th, self.Hp, self.Wp).reshape(
                        nby, self.tpb, TB, self.nbx, self.tpb, TB, self.P).transpose(0, 3, 1, 4, 2, 5, 6).reshape(
                        nby * self.nbx, self.nt, TB, TB, self.P)
                pred = up[locs]
            blocks = self._reconstruct(np.full(locs.size, k), locs, 0, pred, p)
            rows = blocks.reshape(rr.size, self.nbx, B, B, self.P).transpose(0, 2, 1, 3, 4).reshape(
                rr.size, B, self.Wp, self.P)
            self._set_key_rows(s, rr, rows)

    def _parse_key_rows(self, rows: list) -> dict:
        """{key slot: Parsed (that key's rows × nbx lanes of nt tbs, rows ascending)} of the
        block-row streams ``rows`` [(slot, row)], grouped by slot in ascending order."""
        if not rows:
            return {}
        keys = self.lay.keys
        sl = np.array([s for s, _ in rows], np.int64)
        rw = np.array([r for _, r in rows], np.int64)
        kk = np.asarray(keys, np.int64)[sl]
        ci = np.array([self.row_of[int(k)] for k in kk], np.int64)
        ks = self.key_split                              # streams per row: consecutive lanes, row order
        buf, s2, e2 = self._streams(self.key_start[ci, rw].reshape(-1), self.key_end[ci, rw].reshape(-1))
        kind = np.repeat(self.lay.intra[kk].astype(np.int64), ks)
        got = self._parse_streams(buf, s2, e2, self.nt * self.nbx // ks, kind, np.ones(kind.size, np.int64))
        cut = np.flatnonzero(np.diff(sl)) + 1
        bounds = np.concatenate([[0], cut, [sl.size]])
        parts = got.split(bounds * ks)
        return {int(sl[a]): p.reshape((b - a) * self.nbx, self.nt) for p, a, b in zip(parts, bounds[:-1], bounds[1:])}

    def _set_key_rows(self, slot: int, rows: np.ndarray, planes: np.ndarray) -> None:
        """Store decoded block rows ``rows`` (n,) of key slot ``slot``: planes (n, B, Wp, P)."""
        B = self.block_size
        self.keyplanes[slot].reshape(self.nby, B, self.Wp, self.P)[rows] = planes
        if self.atlas is not None:
            self.atlas.set_rows(slot, rows, B, planes)
        self._kp = None
        self._key_done[slot, rows] = True

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

    def _residual(self, views, parsed):
        """(S, nt, 8, 8, P) int32 residuals of parsed streams of ``views``: the nonzero
        coefficients dequantized where they are, then only the 8×8 blocks that have any are
        inverse-transformed."""
        lay, P, nt = self.lay, self.P, self.nt
        S = views.size
        res = np.zeros((S * nt, 64, P), np.int32)            # (S, nt, 8, 8, P) as it is returned
        idx, q = parsed.index, parsed.values
        if idx.size:
            blk, pos = idx >> 6, idx & 63                                    # (lane, tb, plane), scan position
            plane = blk % P
            deq, raster = self._dequantized(q, lay.step16[np.where(self.is_key[views[blk // (nt * P)]], 0, 1), plane],
                                            plane, pos)
            new = np.ones(blk.size, bool)
            new[1:] = blk[1:] != blk[:-1]
            ub = blk[new]                                                    # blocks with coefficients
            X = np.zeros((ub.size, 64), np.float64)
            X[np.cumsum(new) - 1, raster] = deq
            X = self._inverse_rows(X, ub % P)
            res[ub // P, :, ub % P] = X           # (written planes-last: the sum with the prediction
        return res.reshape(S, nt, TB, TB, P)      # then reads it contiguously, 2x faster than a strided view)

    def _inverse_rows(self, X, plane):
        """(n, 64) float64 dequantized 8×8 blocks (raster rows) of planes ``plane`` (n,) → their
        residuals: the inverse transform of the rows of transformed planes, bypassed ones as
        they are (in place where only some rows are transformed)."""
        bypass = self.lay.bypass
        if not bypass.any():
            return inverse_float(X.reshape(-1, TB, TB)).reshape(-1, 64)
        tr = ~bypass[plane]
        if tr.any():
            X[tr] = inverse_float(X[tr].reshape(-1, TB, TB)).reshape(-1, 64)
        return X

    def _dequantized(self, values, q16, plane, pos):
        """(dequantized coefficients clipped to ±COEF_MAX, each one's raster position in its 8×8
        block: zig-zag for transformed planes, as is for bypassed ones) of nonzero levels
        ``values`` at scan positions ``pos`` of planes ``plane``, steps ``q16`` (1/16)."""
        deq = _dequantize_clipped(values, q16)
        bypass = self.lay.bypass
        return deq, (np.where(bypass[plane], pos, ZIGZAG[pos]) if bypass.any() else ZIGZAG[pos])

    def _parse(self, views, locs):
        """Parse the streams of (view, location) pairs that have one."""
        s, e = self.start[views, locs], self.end[views, locs]
        buf, s2, e2 = self._streams(s, e)
        kind = self.lay.intra[views].astype(np.int64)
        key = self.is_key[views].astype(np.int64)
        return self._parse_streams(buf, s2, e2, self.nt, kind, key)

    def _parse_streams(self, buf, s2, e2, nt: int, kind, key):
        """Parsed of streams ``buf[s2[i]:e2[i]]`` of ``nt`` tbs each (one lane per stream): one
        by one or as lanes, whichever :data:`ONE_BY_ONE_RATIO` says is faster."""
        n = e2 - s2
        if n.size and int(n.sum()) < ONE_BY_ONE_RATIO * max(int(n.max()), 1):
            got = [parse_one(bytes(buf[a:b]), self.tables, nt, self._pcl, int(k), int(y))
                   for a, b, k, y in zip(s2.tolist(), e2.tolist(), kind.tolist(), key.tolist())]
            return got[0] if len(got) == 1 else concat_parsed(got)
        return parse_lanes(buf, s2, e2, self.tables, nt, self.pcs, kind, key, self.container.name)

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

    def _add_residual(self, pred, res, modes):
        """Clipped prediction (intra tbs: the flat value) + residual, (S, nt, 8, 8, P) int32.
        Predictions need no clipping: they blend clipped key views with weights summing to 64."""
        base = np.add(pred, res, dtype=np.int32)
        intra = modes == MODE_INTRA                                   # (S, nt): flat value + residual
        if intra.any():
            base[intra] = (res[intra] + self.flat.astype(np.int32)).astype(np.int32)
        # clipped per plane with the bounds tiled over a tb (8·8·P): numpy's inner loop then runs
        # 64·P samples, not P (the (P,) bounds broadcast against the last axis: 7x slower, measured)
        flat = base.reshape(-1, TB * TB * self.P)
        np.minimum(np.maximum(flat, self.lo_tb, out=flat), self.hi_tb, out=flat)   # ufuncs: np.clip costs µs
        return base

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
            slots, wmode, dpos = self._view_refs(v)
            cell = self.lay.cell[v]
            disp, modes = self._maps_of([v])
            warp = None if self.warp_dw is None else view_offsets(self.warp_dw[v], n8y, n8x)
            out = predict_view(self.atlas, slots, wmode[0], disp[cell], modes[cell], dpos, n8y, n8x, out=out,
                               warp=warp)
            self._weigh(out, v)                   # (in place: ``out`` is C-contiguous int32)
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

    def _key_image(self, k: int, threads: int) -> np.ndarray:
        """(Hp, Wp, C) pixels of JPEG 2000 intra key view ``k``, decoded on ``threads`` of
        OpenJPEG's threads (its bytes read under the I/O lock: a byte-range source is shared)."""
        from ..topcodec import decode_image

        a, b = self.img_of[k]
        with self._io:
            data = bytes(self.container.read("tx.keyimg", a, b))
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

    def preparse(self, views, by, bx, level):
        """For a batched call (``views``, ``by``, ``bx`` in the order its chunks take them): its
        coded requests of views with references, to be parsed :data:`PREPARSE_LANES` streams at
        a time as its chunks first need them (:class:`ParseAhead`). The rANS lanes of a parse
        step together, one step per symbol of its longest stream, so fewer and fuller parses
        cost less than one per chunk (BENCHMARKS.md). None where there are too few to gain (or
        at a level without residuals)."""
        if level != 0:
            return None
        loc = by * self.nbx + bx
        have = np.flatnonzero(~self.is_key[views] & self.coded[views, loc])
        if have.size < PREPARSE_MIN:
            return None
        return ParseAhead(self, views[have], loc[have], have, views.size)

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

    def _view_refs(self, v: int):
        """Per-view constants of the scalar path: reference key slots (R,), weights per tb mode
        (R + 1, R) (mode 0: the view's blend weights; mode k: all 64 on reference k − 1),
        position offsets (R, 2)."""
        return self.ref_slots[v], self.wmode[v], self.ref_dpos[v]

    def _block_refs(self, v: int):
        """:func:`rlfc.txsample.block_refs` of view v (cached; None where its references lie in
        more than one atlas group)."""
        got = self._blockref_cache.get(v, False)
        if got is False:
            slots, wmode, dpos = self._view_refs(v)
            got = self._blockref_cache[v] = block_refs(self.atlas, slots, wmode, dpos)
        return got

    def block_pixels(self, view: int, by: int, bx: int, level: int) -> np.ndarray | None:
        """One request's pixels (B, B, P) when its 8×8 blocks are predicted from references in
        one atlas group: :func:`rlfc.txsample.predict_block_pixels`, the same pixels as
        :meth:`block` + ``from_planes`` in about half the numpy calls; a coded block's residual
        (its stream parsed by :func:`rlfc.txparse.parse_one`) is added there too, unless a tb
        of it is intra-coded (then :meth:`block`, with the stream parsed here). None otherwise
        (the caller takes :meth:`block`)."""
        if self.is_key[view] or self.atlas is None:
            return None
        prefs = self._pixel_refs(view)
        if prefs is None:
            return None
        B, loc = self.block_size, by * self.nbx + bx
        res = bounds = None
        if level == 0 and self.coded[view, loc]:
            parsed = self._parse_one(view, loc)
            if (parsed.modes == MODE_INTRA).any():
                return from_planes(self.block(view, by, bx, level, parsed).reshape(B, B, self.P), self.dtype)
            if parsed.index.size:
                res, bounds = self._residual_rows(parsed), self._pixel_bounds
        disp, modes = self._cell_map(self._one_ready(view, by))
        warp = None
        if self.warp_dw is not None:
            wy, wx = self._warp_pixels(view)
            warp = (wy[loc], wx[loc])
        return predict_block_pixels(self.atlas, prefs, disp[loc], modes[loc], by * B, bx * B, self.tpb,
                                    self._peak_f, self.dtype, res, bounds, warp)

    def _warp_pixels(self, view: int) -> tuple:
        """(y, x) warp offsets in pixels of a warped view's (reference, 8×8 block) pairs, block
        by block: each (nby·nbx, R·nt) float32 (sixteenths: exact), row by·nbx + bx the pairs of
        that block, reference-major, 8×8 blocks in raster order (cached per view, for at most
        :data:`WARP_PX_VIEWS` views at once: 8·R bytes per 8×8 block each)."""
        got = self._warp_px_cache.get(view)
        if got is None:
            if len(self._warp_px_cache) >= WARP_PX_VIEWS:
                self._warp_px_cache.clear()
            t, ny, nx = self.tpb, self.nby, self.nbx
            R = self.warp_dw.shape[1]

            def blocks(o):
                o = o.reshape(R, ny, t, nx, t).transpose(1, 3, 0, 2, 4).reshape(ny * nx, R * t * t)
                return (o * 0.0625).astype(np.float32)

            oy, ox = view_offsets(self.warp_dw[view], self.nby8, self.nbx8)
            got = self._warp_px_cache[view] = (blocks(oy), blocks(ox))
        return got

    def _residual_rows(self, parsed) -> np.ndarray:
        """:meth:`_residual_one` of a stream of a view with references laid out as
        :func:`rlfc.txsample.predict_block_pixels` adds it: (nt·64, C) in the atlas's float type
        (C its channels; 0 past the P planes), 8×8 blocks and their samples in raster order.
        Values past 2^24 may round in float32; the sum with the prediction is then past the
        planes' bounds either way and clips alike."""
        nt, P, C = self.nt, self.P, self.atlas.C
        idx = parsed.index
        at, q16 = self._res_tables()                  # (per index g·64 + scan position: its place, its step)
        X = np.zeros((nt * P, 64))
        X.reshape(-1)[at[idx]] = _dequantize_clipped(parsed.values, q16[idx])
        res = np.zeros((nt, 64, C), self.atlas.ftype)
        res[..., :P] = self._inverse_rows(X, self._row_planes).reshape(nt, P, 64).transpose(0, 2, 1)
        return res.reshape(nt * 64, C)

    def _res_tables(self) -> tuple:
        """Per index g·64 + scan position of a block's coefficients (g = tb·P + plane): its place
        in (nt·P, 64) raster rows (zig-zag for transformed planes, as is for bypassed ones) and
        its step (1/16) in a view with references: :meth:`_residual_rows`' look-ups (cached)."""
        got = self._res_tab
        if got is None:
            g = np.arange(self.nt * self.P)
            raster = np.where(self.lay.bypass[self._row_planes][:, None], np.arange(64), ZIGZAG[None, :])
            got = self._res_tab = (((g * 64)[:, None] + raster).reshape(-1), np.repeat(self._q16_rows, 64))
        return got

    def _pixel_refs(self, view: int):
        """:func:`rlfc.txsample.block_pixel_refs` of a view (cached; None where its references
        lie in more than one atlas group)."""
        prefs = self._pixref_cache.get(view, False)
        if prefs is False:
            refs = self._block_refs(view)
            prefs = self._pixref_cache[view] = None if refs is None else \
                block_pixel_refs(self.atlas, refs, self.tpb, self.lay.wp[view] if self._weighted[view] else None,
                                 self.lo, self.hi)
        return prefs

    def _cell_map(self, cell: int) -> tuple:
        """(disparities as float32, modes) of a decoded map, block-major: (nby·nbx, nt), row
        by·nbx + bx the 8×8 blocks of block (by, bx) in raster order (cached; a request reads
        one row, a view)."""
        dm = self._cell_maps.get(cell)
        if dm is None:
            t, ny, nx = self.tpb, self.nby, self.nbx

            def blocks(a):
                return np.ascontiguousarray(a.reshape(ny, t, nx, t).swapaxes(1, 2)).reshape(ny * nx, t * t)

            dm = self._cell_maps[cell] = (blocks(self._map_store.disp[cell].astype(np.float32)),
                                          blocks(self._map_store.modes[cell].astype(np.uint8)))
        return dm

    def _one_rows(self, view: int, by: int) -> None:
        """For one request: the key-view rows its block row reaches, decoded where they are not
        yet (a scalar check: the one-request paths are lean)."""
        if not self._keys_all and not self._rows_ok[view, by]:
            self._have_rows(np.array([view]), np.array([by]))

    def _one_ready(self, view: int, by: int) -> int:
        """For one request of a view with references: :meth:`_one_rows`, and the view's map
        decoded where it is not yet (a scalar check, not :meth:`_maps_of`); returns the map."""
        self._one_rows(view, by)
        cell = self.lay.cell[view]
        if not self._map_done[cell]:                    # (not _maps_of: a scalar check)
            self._have_maps(np.array([cell]))
        return cell

    def block(self, view: int, by: int, bx: int, level: int, parsed=None) -> np.ndarray:
        """One request, lean: the prediction of the block's nt tbs from every reference at once
        (one remap call), plus at most one parsed stream (``parsed``: the caller parsed it); the
        same integers as :meth:`blocks`."""
        B, P, tpb = self.block_size, self.P, self.tpb
        if self.is_key[view]:
            self._one_rows(view, by)
            s = self.key_slot[view]
            return self.keyplanes[s, by * B:(by + 1) * B, bx * B:(bx + 1) * B].reshape(B * B, P)
        cell = self._one_ready(view, by)
        disp, modes = self._map_store.disp, self._map_store.modes
        loc8 = (by * tpb * self.nbx8 + bx * tpb) + self._tb_off              # (nt,) raster within the block
        refs = self._block_refs(view) if self.atlas is not None and self.warp_dw is None else None
        if refs is not None:                                # the remap kernel, every reference at once
            out = predict_block(self.atlas, refs, disp[cell, loc8], modes[cell, loc8],
                                self._tb_y + np.float32(by * B), self._tb_x + np.float32(bx * B))
        else:                  # references in several atlas groups, or key views too large for OpenCV
            slots, wmode, dpos = self._view_refs(view)
            ty = by * tpb + self._tby
            tx = bx * tpb + self._tbx
            dd = disp[cell, loc8][:, None, None] * dpos[None]          # (nt, R, 2)
            dy, dx = dd[..., 0], dd[..., 1]
            if self.warp_dw is not None:               # (a warped view: each reference's offset, per 8×8 block)
                oy, ox = offsets(np.broadcast_to(self.warp_dw[view], (ty.size,) + self.warp_dw.shape[1:]), ty, tx)
                dy, dx = dy + oy, dx + ox
            args = (np.broadcast_to(slots, (ty.size, slots.size)), wmode[modes[cell, loc8]], dy, dx, ty * TB, tx * TB)
            out = remap_predict(self.atlas, *args) if self.atlas is not None else \
                predict_tbs(NUMPY, self.kp, (self.Hp, self.Wp), *args)
        out = self._weigh(out, view)
        loc = by * self.nbx + bx
        if level == 0 and self.coded[view, loc]:
            if parsed is None:
                parsed = self._parse_one(view, loc)
            out = self._add_residual(out[None], self._residual_one(view, parsed)[None], parsed.modes)[0]
        return out.reshape(tpb, tpb, TB, TB, P).transpose(0, 2, 1, 3, 4).reshape(B * B, P)

    def _parse_one(self, view: int, loc: int):
        """:meth:`_parse` of one request's stream (a scalar range: no arrays around it)."""
        if self._remote:
            return self._parse(np.array([view]), np.array([loc]))
        s, e = int(self.start[view, loc]), int(self.end[view, loc])
        with self._io:
            if e > s:
                self.container.verify_span("tx.blocks", s, e)
        return parse_one(bytes(self.buf[s:e]), self.tables, self.nt, self._pcl, int(self.lay.intra[view]),
                         int(self.is_key[view]))

    def _residual_one(self, view: int, parsed) -> np.ndarray:
        """:meth:`_residual` of one parsed stream, (nt, 8, 8, P) int32: every 8×8 block of the
        request transformed at once (a block without coefficients transforms to exact zeros), in
        about half the numpy calls."""
        lay, P, nt = self.lay, self.P, self.nt
        idx = parsed.index
        if not idx.size:
            return np.zeros((nt, TB, TB, P), np.int32)
        g, pos = idx >> 6, idx & 63                                          # tb·P + plane, scan position
        plane = g % P
        deq, raster = self._dequantized(parsed.values, lay.step16[0 if self.is_key[view] else 1][plane], plane, pos)
        X = np.zeros((nt * P, 64))
        X[g, raster] = deq
        X = self._inverse_rows(X, self._row_planes)
        return X.reshape(nt, P, 64).transpose(0, 2, 1).astype(np.int32).reshape(nt, TB, TB, P)

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
                "warped_views": 0 if lay.warp is None else int(lay.warp.any(axis=1).sum())}


class ParseAhead:
    """The coded requests of one batched call (streams of views with references), parsed in
    groups of :data:`PREPARSE_LANES` streams, each group once, by the first chunk that needs it
    (others that need it wait; chunks on other threads predict meanwhile).

    Args:
        core: the :class:`TxDecoder`; views, locs: (S,) the coded requests' views and block
            locations, in the call's order; at: (S,) their places among the call's M requests.
    """

    def __init__(self, core, views, locs, at, M: int):
        self.core, self.views, self.locs = core, views, locs
        self.lane = np.full(M, -1, np.int64)
        self.lane[at] = np.arange(at.size)
        n = -(-at.size // PREPARSE_LANES)
        self.parsed: list = [None] * n                 # per group: (Parsed, its lane bounds)
        self.locks = [threading.Lock() for _ in range(n)]

    def _group(self, g: int) -> tuple:
        with self.locks[g]:
            if self.parsed[g] is None:
                a, b = g * PREPARSE_LANES, (g + 1) * PREPARSE_LANES
                p = self.core._parse(self.views[a:b], self.locs[a:b])
                self.parsed[g] = (p, p.lane_bounds())
            return self.parsed[g]

    def chunk(self, idx: np.ndarray) -> tuple:
        """(places within ``idx`` of its coded requests, their Parsed) for the call's requests
        ``idx`` (ascending, as the decoder's chunks take them; else those streams are parsed
        on their own)."""
        lane = self.lane[idx]
        have = np.flatnonzero(lane >= 0)
        lane = lane[have]
        if not lane.size:
            return have, None
        if lane.size > 1 and (np.diff(lane) <= 0).any():      # (not in the call's order: parsed as they are)
            return have, self.core._parse(self.views[lane], self.locs[lane])
        parts = []
        for g in range(int(lane[0]) // PREPARSE_LANES, int(lane[-1]) // PREPARSE_LANES + 1):
            p, bounds = self._group(g)
            sel = lane[(lane >= g * PREPARSE_LANES) & (lane < (g + 1) * PREPARSE_LANES)]
            parts.append(p.take(sel - g * PREPARSE_LANES, bounds))
        return have, parts[0] if len(parts) == 1 else concat_parsed(parts)


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
