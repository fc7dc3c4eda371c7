"""The ``tx`` profile's decoder on a torch device (:meth:`rlfc.profiles.tx.TxDecoder.torch`): the
same planes as the numpy decoder, the prediction, dequantization and inverse transform on the
device."""
from __future__ import annotations

import os
import threading

import numpy as np

from ..kernels import dequantize
from ..transform import COEF_MAX, ZIGZAG, inverse_float
from ..txpredict import TB, predict_tbs
from ..txparse_torch import pair_words, parse_lanes_torch
from ..txsyntax import MODE_INTRA
from ..xp import shared
from .tx import TxDecoder, pred_inputs

#: streams in a torch call from which a CUDA device parses them itself (measured on an H100,
#: µs per block parsed on the host / on the device: lytro_dino_2067's 53 streams in 20 000
#: requests 0.48 / 0.91; stanford_chess's 5 800 in 200 000, two runs, 0.42 / 0.41 and 0.33 /
#: 0.42; stanford_lytro_general_11's 12 800 in 20 000, 15.9 / 1.1 and 18.8 / 1.4)
DEVICE_PARSE_MIN = 8192


class TorchTx:
    """The same planes on a torch device: key views, maps and tables copied once; streams are
    parsed on the CPU (rANS lanes), prediction, dequantization and the inverse transform run
    on the device (the kernels of :mod:`rlfc.txpredict` and :mod:`rlfc.transform`)."""

    def __init__(self, dec: TxDecoder, device):
        from ..xp import torch_backend

        dec.decode_keys()                      # the device holds every key view

        self.d = dec
        self.xp = torch_backend(device)
        self.kp = self.xp.asarray(dec.kp)
        self.keyplanes = self.xp.asarray(dec.keyplanes)
        self.flat = self.xp.asarray(dec.flat)
        self.lo, self.hi = self.xp.asarray(dec.lo), self.xp.asarray(dec.hi)
        # weighted prediction (version 4): (N0, P) gains and offsets, int32
        self.wp = None if dec.lay.wp is None else tuple(self.xp.asarray(dec.lay.wp[..., i].astype(np.int32))
                                                        for i in (0, 1))
        # the request bookkeeping of a call runs on the device, from these tables (the host's
        # numpy indexing over every 8×8 block of a call was most of a batched GPU decode)
        self.tables = tuple(self.xp.asarray(a) for a in dec.pred_tables())
        # residual streams parsed where they are reconstructed: on a GPU, not on the host (whose
        # numpy parse was 92% of a call on grids whose blocks carry residuals), for calls of at
        # least this many streams (fewer parse faster on the host, overlapped with the device's
        # prediction); None: always on the host. LFC_DEVICE_PARSE = 1 / 0 forces either way (the
        # CPU device parses faster in numpy)
        env = os.environ.get("LFC_DEVICE_PARSE")
        cuda_min = DEVICE_PARSE_MIN if self.xp.device.type == "cuda" else None
        self.device_parse_min = cuda_min if env is None else (0 if env == "1" else None)
        self.triton = None                  # the Triton magnitude kernel: None = where CUDA and Triton are
        self._section = None
        self._res_consts = None
        self._lock = threading.Lock()

    def _parse_host(self, views, locs):
        """What the streams of (view, location) pairs (numpy) need uploaded, as a list of
        int64-able numpy arrays, and how :meth:`_parse_device` reads them back: parsed here
        (numpy lanes: modes, index, values) or, per :attr:`device_parse_min`, only located here
        (their starts and ends in the device's copy of the section, view kinds and key flags) and
        parsed on the device. Checksums are verified here."""
        d, xp = self.d, self.xp
        if self.device_parse_min is None or views.size < self.device_parse_min:
            parsed = d._parse(views, locs)
            return [parsed.modes.reshape(-1), parsed.index, parsed.values], ("host", views.size, parsed.index.size)
        buf, s2, e2 = d._streams(d.start[views, locs], d.end[views, locs])     # checksums verified here
        if buf is d.buf:                                  # the whole section: copied to the device once
            with self._lock:                              # (chunks may be in flight on two threads)
                if self._section is None:
                    dbuf = xp.asarray(buf)
                    self._section = shared(dbuf, pair_words(dbuf))
            section = self._section
        else:                                             # a byte-range source: this call's streams
            dbuf = xp.asarray(buf)
            section = (dbuf, pair_words(dbuf))
        return [s2, e2, d.lay.intra[views], d.is_key[views]], ("device", views.size, section)

    def _parse_device(self, how, parts):
        """(modes (S, nt), index (K,), values (K,)) int64 device tensors, as
        :class:`rlfc.txparse.Parsed` holds them (the nonzero levels, sparse), from
        :meth:`_parse_host`'s arrays uploaded (``parts``)."""
        d = self.d
        kind, S, extra = how
        if kind == "host":
            return parts[0].reshape(S, d.nt), parts[1], parts[2]
        dbuf, w16 = extra
        return parse_lanes_torch(dbuf, w16, parts[0], parts[1], d.tables, d.nt, d.pcs, parts[2], parts[3],
                                 d.container.name, self.triton)

    def _add_residual(self, pred, hv, notkey, modes, index, values):
        """``pred`` (n, nt, 8, 8, P) int64 with the parsed residuals of its rows ``hv`` (S,)
        added (``notkey`` (S,): 1 where the row's view is not a key view; device tensors), as
        :meth:`TxDecoder._residual` and :meth:`TxDecoder._add_residual` do (clipping comes
        after): intra tbs start from the flat value; the nonzero coefficients are dequantized
        where they are, and only the 8×8 blocks that have any are inverse-transformed (float64,
        exact) and added in place. Nothing here waits for the device."""
        import torch

        d, xp = self.d, self.xp
        nt, P = d.nt, d.P
        i64 = dict(dtype=torch.int64, device=xp.device)
        intra = torch.zeros(pred.shape[:2], dtype=torch.bool, device=xp.device)
        intra[hv] = modes == MODE_INTRA                 # a select over every tb: no count to wait for
        pred = torch.where(intra[:, :, None, None, None], self.flat.to(torch.int64), pred).contiguous()   # (viewed flat below)
        with self._lock:
            if self._res_consts is None:
                lay = d.lay
                self._res_consts = shared(xp.asarray(lay.step16.astype(np.int64)), xp.asarray(lay.bypass),
                                          xp.asarray(ZIGZAG), torch.arange(0, 64 * P, P, **i64))
        step16, bypass, zigzag, cols = self._res_consts
        blk, pos = index >> 6, index & 63                                    # (lane, tb, plane), scan position
        plane = blk % P
        deq = dequantize(xp, values, step16[notkey[blk // (nt * P)], plane]).clamp_(-COEF_MAX, COEF_MAX)
        new = torch.ones_like(blk, dtype=torch.bool)
        new[1:] = blk[1:] != blk[:-1]
        ub = blk[new]                                                        # blocks with coefficients
        X = torch.zeros((ub.numel(), 64), dtype=torch.float64, device=xp.device)
        X[torch.cumsum(new, 0) - 1, torch.where(bypass[plane], pos, zigzag[pos])] = deq.to(torch.float64)
        if d.lay.bypass.any():
            tr = ~bypass[ub % P]
            X[tr] = inverse_float(X[tr].reshape(-1, TB, TB)).reshape(-1, 64)
        else:
            X = inverse_float(X.reshape(-1, TB, TB)).reshape(-1, 64)
        g = ub // P                                                          # lane · nt + tb
        first = ((hv[g // nt] * nt + g % nt) * 64) * P + ub % P            # flat (n, nt, 8, 8, P) of pixel 0
        return pred.view(-1).index_add_(0, (first[:, None] + cols).reshape(-1), X.to(torch.int64).reshape(-1)).view(
            pred.shape)

    def _pred(self, v, locs):
        """As :meth:`TxDecoder._pred` of :meth:`TxDecoder._tb_coords`: ``v``, ``locs`` (n,) int64
        device tensors of requests → (n·nt, 8, 8, P) int32, the same integers."""
        d = self.d
        args = pred_inputs(self.tables, d.nbx8, *d._tb_coords(v, locs, self.xp))
        p = predict_tbs(self.xp, self.kp, (d.Hp, d.Wp), *args)
        if self.wp is None:
            return p
        import torch

        vv = torch.repeat_interleave(v, d.nt)                # each 8×8 block's view (as _tb_coords)
        g, o = (a[vv][:, None, None, :] for a in self.wp)
        p = ((p * g + 32) >> 6) + o                          # (int32: planes within ±2^16, gains < 2^7)
        return torch.minimum(torch.maximum(p, self.lo.to(p.dtype)), self.hi.to(p.dtype))

    def blocks(self, views, by, bx, level):
        """(M,) validated numpy requests → (M, B·B, P) int32 tensor. Everything the device needs
        from the host goes up in one copy (a copy from pageable memory waits for the kernels
        queued before it); the residual streams are parsed first (their parse waits for the
        device where sizes depend on the data), then the prediction and the residuals are queued
        without waiting."""
        import torch

        d, xp = self.d, self.xp
        M, B, nt, P = views.size, d.block_size, d.nt, d.P
        out = torch.empty((M, B, B, P), dtype=torch.int32, device=xp.device)
        key = d.is_key[views]
        kk, nk = np.flatnonzero(key), np.flatnonzero(~key)
        v, locs = views[nk], by[nk] * d.nbx + bx[nk]
        have = np.flatnonzero(d.coded[v, locs]) if level == 0 and nk.size else np.zeros(0, np.int64)
        parts = [kk, by[kk], bx[kk], d.key_slot[views[kk]], nk, v, locs, have, ~d.is_key[v[have]]]
        how = None
        if have.size:
            more, how = self._parse_host(v[have], locs[have])
            parts += more
        sizes = [p.size for p in parts]
        up = xp.asarray(np.concatenate([p.astype(np.int64, copy=False) for p in parts]))      # one upload
        kk_t, kby, kbx, kslot, nk_t, v_t, locs_t, hv, notkey, *rest = torch.split(up, sizes)
        if kk.size:                                   # key views: gather the blocks, not whole planes
            ar = torch.arange(B, dtype=torch.int64, device=xp.device)
            ys, xs = kby[:, None] * B + ar, kbx[:, None] * B + ar
            out[kk_t] = self.keyplanes[kslot[:, None, None], ys[:, :, None], xs[:, None, :]]
        if nk.size:
            parsed = self._parse_device(how, rest) if have.size else None
            pred = self._pred(v_t, locs_t).reshape(nk.size, nt, TB, TB, P).to(torch.int64)
            if parsed is not None:
                pred = self._add_residual(pred, hv, notkey, *parsed)
            rec = torch.maximum(torch.minimum(pred, self.hi), self.lo).to(torch.int32)
            out[nk_t] = rec.reshape(nk.size, d.tpb, d.tpb, TB, TB, P).permute(0, 1, 3, 2, 4, 5).reshape(nk.size, B, B, P)
        return out.reshape(M, B * B, P)


__all__ = ["TorchTx"]
