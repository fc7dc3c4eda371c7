"""What a ``tx`` decoder decodes only when a request first needs it (:class:`OnDemand`, a part of
:class:`rlfc.profiles.tx.TxDecoder`): the disparity maps, cell by cell, and the key views, block
row by block row (the rows a request's prediction reaches through its map)."""
from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np

from formats.parallel import LOCAL_THREADS

from ..txpredict import DISP_BITS, TB, upsample_thumb
from ..txwarp import max_row_offset

KEY_PARSE_TBS = 1 << 20  # tbs of key-view rows parsed together (bounds the parsed coefficients held)
#: a key with references whose rows are decoded this many at a time or more has them predicted in
#: raster bands (:meth:`TxDecoder._key_rows_planes`: 0.59–0.95× on whole keys of five grids); fewer
#: go block by block, as the requests of other views (1–4 rows: raster 0.98–1.19×; BENCHMARKS.md)
KEY_ROWS_RASTER_MIN = 8
#: pixels of whole JPEG 2000 views kept after a whole-view decode (:meth:`OnDemand.image_pixels`;
#: a posed capture's 960×540 RGB view is 1.5 MiB)
IMAGE_CACHE_BYTES = 64 << 20


class OnDemand:
    """Maps and key-view block rows decoded on first use."""

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
        return self.cell_map(cell)

    def cell_map(self, cell: int) -> np.ndarray:
        """(nby8, nbx8) int64 disparity map ``cell`` (1/16 px per view step; decoded now if not
        yet), whether or not a view is predicted through it (a file whose every view is coded
        alone keeps its maps, the shared one in every cell: the renderer's geometry)."""
        if not 0 <= cell < self.lay.n_maps:
            raise ValueError(f"map {cell} is not one of the file's {self.lay.n_maps}")
        if not self._map_done[cell]:
            self._have_maps(np.array([cell], np.int64))
        return self._map_store.disp[cell].reshape(self.nby8, self.nbx8)

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

    def image_views(self, views: np.ndarray) -> np.ndarray:
        """(n,) bool: which of ``views`` (flat indices) :meth:`image_pixels` decodes straight to
        pixels: JPEG 2000 intra key views that no view is predicted from (a posed capture's
        views; a grid's views promoted to JPEG 2000) and whose planes are not decoded yet.
        Their whole-view decodes then skip the planes (YCoCg-R there and back: lossless, so the
        same pixels); a block request still decodes and keeps the planes."""
        views = np.asarray(views, np.int64)
        ok = self._direct[views]
        ok[ok] = ~self._key_done[self.key_slot[views[ok]]].any(axis=1)
        return ok

    def image_pixels(self, v: int, threads: int = 1) -> np.ndarray:
        """(Hp, Wp, C) pixels of view ``v``, one of :meth:`image_views`, decoded from its
        JPEG 2000 codestream on ``threads`` of OpenJPEG's threads, and kept in a cache of
        :data:`IMAGE_CACHE_BYTES` (least recently used out first: a viewer stepping back to a
        view copies it; read-only, callers copy)."""
        v = int(v)
        px = self._cached_image(v)
        if px is not None:
            return px
        px = self._key_image(v, threads)
        px.flags.writeable = False
        with self._img_lock:
            if v not in self._img_cache and px.nbytes <= IMAGE_CACHE_BYTES:
                self._img_cache[v] = px
                self._img_bytes += px.nbytes
                while self._img_bytes > IMAGE_CACHE_BYTES:
                    self._img_bytes -= self._img_cache.popitem(last=False)[1].nbytes
        return px

    def _cached_image(self, k: int) -> np.ndarray | None:
        """The pixels :meth:`image_pixels` kept of JPEG 2000 view ``k`` (now the most recently
        used), or None."""
        with self._img_lock:
            px = self._img_cache.get(k)
            if px is not None:
                self._img_cache.move_to_end(k)
        return px

    def _need_views(self, views: np.ndarray) -> np.ndarray:
        """(n_keys, nby) bool: every block row of the key views that whole ``views`` read."""
        need = np.zeros(self._key_done.shape, bool)
        for v in sorted(set(np.asarray(views).tolist())):     # (np.unique imports numpy.ma on a first call)
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

        images = [keys[s] for s in range(len(keys)) if keys[s] in self.img_of and need[s].any()
                  and keys[s] not in self._img_cache]          # (kept pixels of a whole-view decode: no decode)
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
                img = got[k].result() if k in got else self._cached_image(k)
                self._set_key_image(k, img if img is not None else self._key_image(k, LOCAL_THREADS))
                continue
            if s not in parsed:
                parse_next()
            p = parsed.pop(s)
            if not lay.intra[k] and self.atlas is not None and rr.size >= KEY_ROWS_RASTER_MIN:
                self._set_key_rows(s, rr, self._key_rows_planes(k, rr, p))
                continue
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
