"""One random-access request of a ``tx`` file, lean (:class:`SingleRequests`, a part of
:class:`rlfc.profiles.tx.TxDecoder`): a single block predicted in one remap call, and its one
stream parsed in plain Python, in as few numpy calls as the same integers allow."""
from __future__ import annotations

import numpy as np

from formats.pixels import from_planes

from ..kernels import dequantize
from ..transform import COEF_MAX, ZIGZAG, inverse_interleaved
from ..txpredict import TB, predict_tbs
from ..txparse_one import parse_one, parse_one_rows
from ..txsample import predict as remap_predict
from ..txsample_block import block_pixel_refs, block_refs, predict_block, predict_block_pixels
from ..txsyntax import MODE_INTRA
from ..txwarp import offsets, view_offsets
from ..xp import NUMPY

#: views whose warp offsets the lean single-block path keeps (:meth:`TxDecoder._warp_pixels`;
#: 128 KiB a view of 512² pixels)
WARP_PX_VIEWS = 64


def _dequantize_clipped(values, q16) -> np.ndarray:
    """:func:`rlfc.kernels.dequantize` of levels ``values`` at steps ``q16`` (1/16; numpy), clipped
    to ±COEF_MAX."""
    deq = dequantize(NUMPY, values, q16)
    return np.minimum(np.maximum(deq, -COEF_MAX, out=deq), COEF_MAX, out=deq)


class SingleRequests:
    """The one-request paths: :meth:`block` (planes) and :meth:`block_pixels` (pixels)."""

    def _view_refs(self, v: int):
        """Per-view constants of the scalar path: reference key slots (R,), weights per tb mode
        (R + 1, R) (mode 0: the view's blend weights; mode k: all 64 on reference k − 1),
        position offsets (R, 2)."""
        return self.ref_slots[v], self.wmode[v], self.ref_dpos[v]

    def _block_refs(self, v: int):
        """:func:`rlfc.txsample_block.block_refs` of view v (cached; None where its references lie in
        more than one atlas group)."""
        got = self._blockref_cache.get(v, False)
        if got is False:
            slots, wmode, dpos = self._view_refs(v)
            got = self._blockref_cache[v] = block_refs(self.atlas, slots, wmode, dpos)
        return got

    def block_pixels(self, view: int, by: int, bx: int, level: int) -> np.ndarray | None:
        """One request's pixels (B, B, P) when its 8×8 blocks are predicted from references in
        one atlas group: :func:`rlfc.txsample_block.predict_block_pixels`, the same pixels as
        :meth:`block` + ``from_planes`` in about half the numpy calls; a coded block's residual
        (its stream parsed by :func:`rlfc.txparse_one.parse_one_rows`) is added there too, unless a tb
        of it is intra-coded (then :meth:`block`, with the stream parsed here). None otherwise
        (the caller takes :meth:`block`)."""
        if self.atlas is None:
            return None
        ready = self._pix_ready.get(view)
        if ready is None:
            if self.is_key[view]:
                return None
            prefs = self._pixel_refs(view)
            if prefs is None:
                return None
            ready = (prefs,) + self._cell_map(self._one_ready(view, by))
            if self._keys_all:                  # (every key row and this view's map decoded: nothing
                self._pix_ready[view] = ready   # left to check for its later requests)
        prefs, disp, modes, dmax = ready
        B, loc = self.block_size, by * self.nbx + bx
        res = bounds = None
        if level == 0 and self.coded[view, loc]:
            _, places, vals = self._parse_rows(view, loc)
            if vals is None:                  # (an intra tb, rare: the planes' path, with the Parsed)
                return from_planes(self.block(view, by, bx, level, places).reshape(B, B, self.P), self.dtype)
            if len(places):
                res, bounds = self._residual_pixels(places, vals), self._pixel_bounds
        warp = None
        if self.warp_dw is not None:
            wy, wx = self._warp_pixels(view)
            warp = (wy[loc], wx[loc])
        return predict_block_pixels(self.atlas, prefs, disp[loc], modes[loc], by * B, self.tpb, self._peak_f,
                                    self.dtype, res, bounds, warp, dmax, self._pix_depth)

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

    def _parse_rows(self, view: int, loc: int) -> tuple:
        """The stream of a request of a view with references (not a key view), parsed and
        dequantized for :meth:`_residual_pixels`: (its tbs' modes as a list, each nonzero
        coefficient's place, its value); where a tb is intra-coded (the modes, the stream's
        :class:`rlfc.txparse.Parsed`, None) (:func:`rlfc.txparse_one.parse_one_rows`)."""
        if self._remote:
            return self._rows_of(self._parse_one(view, loc))
        return parse_one_rows(self._stream_bytes(view, loc), self.tables, self.nt, self._pcl,
                              int(self.lay.intra[view]), int(self.is_key[view]), self._res_tables())

    def _rows_of(self, parsed) -> tuple:
        """:meth:`_parse_rows` of a :class:`rlfc.txparse.Parsed` of one stream (numpy)."""
        _, _, place, q16 = self._res_tables()
        modes = parsed.modes[0].tolist()
        if MODE_INTRA in modes:
            return modes, parsed, None
        idx = parsed.index
        return modes, place[idx], _dequantize_clipped(parsed.values, q16[idx >> 6])

    def _residual_pixels(self, places, vals) -> np.ndarray:
        """One request's residual as :func:`rlfc.txsample_block.predict_block_pixels` adds it:
        (nt·64, C) float64 integers (C the atlas's channels; 0 past the P planes), 8×8 blocks and
        their samples in raster order, from dequantized coefficients ``vals`` at ``places`` in
        that layout (:meth:`_res_tables`): every 8×8 block inverse-transformed at once with its
        channels interleaved (:func:`rlfc.transform.inverse_interleaved`; a block without
        coefficients transforms to exact zeros), planes that bypass the transform as they are.
        float64: the prediction's float32 sum takes it rounded once (values past 2^24, which may
        round, put the sum past the planes' bounds either way, and it clips alike)."""
        C = self.atlas.C
        X = np.zeros((self.nt, TB, TB * C))
        X.reshape(-1)[places] = vals
        bp = self._bypass_c
        if bp is None:
            return inverse_interleaved(X, C).reshape(-1, C)
        if bp.all():
            return X.reshape(-1, C)
        R = inverse_interleaved(X, C).reshape(-1, C)
        R[:, bp] = X.reshape(-1, C)[:, bp]
        return R

    def _res_tables(self) -> tuple:
        """Per index g·64 + scan position of a block's coefficients (g = tb·P + plane): its place
        in :meth:`_residual_pixels`' (nt, 8, 8, C) layout (zig-zag for transformed planes, as is
        for bypassed ones); per g: its step (1/16) in a view with references. Each as a list and
        as an int64 array (cached)."""
        got = self._res_tab
        if got is None:
            nt, P, C = self.nt, self.P, self.atlas.C
            tb, plane = np.divmod(np.arange(nt * P), P)
            raster = np.where(self.lay.bypass[plane][:, None], np.arange(64), ZIGZAG[None, :])
            place = ((tb * 64 * C)[:, None] + raster * C + plane[:, None]).reshape(-1)
            q16 = np.asarray(self._q16_rows, np.int64)
            got = self._res_tab = (place.tolist(), q16.tolist(), place, q16)
        return got

    def _pixel_refs(self, view: int):
        """:func:`rlfc.txsample_block.block_pixel_refs` of a view (cached; None where its references
        lie in more than one atlas group)."""
        prefs = self._pixref_cache.get(view, False)
        if prefs is False:
            refs = self._block_refs(view)
            prefs = self._pixref_cache[view] = None if refs is None else \
                block_pixel_refs(self.atlas, refs, self.tpb, self.lay.wp[view] if self._weighted[view] else None,
                                 self.lo, self.hi)
        return prefs

    def _cell_map(self, cell: int) -> tuple:
        """A decoded map block-major, row by·nbx + bx the 8×8 blocks of block (by, bx) in raster
        order: its disparities as float32 followed by the block's pixel origin (by·B, bx·B)
        (nby·nbx, nt + 2), its modes (nby·nbx, nt), and its largest |disparity| (a float)
        (cached; a request reads one row, a view)."""
        dm = self._cell_maps.get(cell)
        if dm is None:
            t, ny, nx = self.tpb, self.nby, self.nbx

            def blocks(a):
                return np.ascontiguousarray(a.reshape(ny, t, nx, t).swapaxes(1, 2)).reshape(ny * nx, t * t)

            dc = self._map_store.disp[cell]
            org = np.stack(np.meshgrid(np.arange(ny) * self.block_size, np.arange(nx) * self.block_size,
                                       indexing="ij"), axis=-1).reshape(ny * nx, 2)
            dm = self._cell_maps[cell] = (np.concatenate([blocks(dc.astype(np.float32)), org.astype(np.float32)],
                                                         axis=1),
                                          blocks(self._map_store.modes[cell].astype(np.uint8)),
                                          float(max(int(dc.max(initial=0)), -int(dc.min(initial=0)))))
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
        return parse_one(self._stream_bytes(view, loc), self.tables, self.nt, self._pcl, int(self.lay.intra[view]),
                         int(self.is_key[view]))

    def _stream_bytes(self, view: int, loc: int) -> bytes:
        """A request's stream from the file held in memory, its chunk verified first (a scalar
        range: no arrays around it)."""
        s, e = int(self.start[view, loc]), int(self.end[view, loc])
        with self._io:
            if e > s:
                self.container.verify_span("tx.blocks", s, e)
        return bytes(self.buf[s:e])

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
