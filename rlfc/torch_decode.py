"""Batched RLFC block decode with torch, on a GPU when one is present.

The compressed blocks section and the top key views are copied to the device once (the file
stays compressed there); headers are located with the same vectorized numpy code as the CPU
decoder (:meth:`rlfc.blocks.BlockStore.locate`); BISE / plain-bit unpacking, dequantization,
accumulation down the tree and the YCoCg-R inverse run on the device. Integer arithmetic only,
so the result equals :meth:`rlfc.decoder.RlfcDecoder.decode_blocks` bit for bit.
"""
from __future__ import annotations

import numpy as np
import torch

from formats.errors import ChecksumError, ParameterError

from .bise import _group_layout
from .bise_tables import QUINT_DIGITS, RANGE_VALUES, RANGES, TRIT_DIGITS
from .blocks import MODE_CONST, MODE_PLAIN
from .color import forward_int, inverse_int


def _gather_word(buf: torch.Tensor, byte: torch.Tensor, nbytes: int) -> torch.Tensor:
    """Little-endian int64 word of ``nbytes`` bytes starting at each byte offset."""
    w = buf[byte].to(torch.int64)
    for i in range(1, nbytes):
        w = w | (buf[byte + i].to(torch.int64) << (8 * i))
    return w


class TorchBlockDecoder:
    """Batched block decoder on a torch device, over an :class:`~rlfc.decoder.RlfcDecoder`.

    Args:
        dec: an opened RLFC decoder (memory-mapped or in-memory file).
        device: torch device; default "cuda" when available, else "cpu".
    """

    def __init__(self, dec, device: str | None = None):
        if dec.store is None:
            raise ParameterError("the torch decoder needs the whole file (not a byte-range source)")
        self.d = dec
        self.dev = torch.device(device or ("cuda" if torch.cuda.is_available() else "cpu"))
        dec.file.container.verify_ranges("rlfc.blocks", np.array([0]), np.array([int(dec._index[-1])]))
        self.buf = torch.from_numpy(np.array(dec.store.buf, dtype=np.uint8)).to(self.dev)
        self.top = torch.from_numpy(dec.top_blocks.astype(np.int32)).to(self.dev)   # (N_H, nby, nbx, B·B, P)
        self.q16 = torch.from_numpy(dec.q16.astype(np.int64)).to(self.dev)
        self.trit = torch.from_numpy(TRIT_DIGITS.astype(np.int64)).to(self.dev)
        self.quint = torch.from_numpy(QUINT_DIGITS.astype(np.int64)).to(self.dev)
        self.peak = int(np.iinfo(dec.dtype).max)
        if dec.profile == "dcp":      # key views (planar), disparities and offsets on the device
            self.top_planar = torch.from_numpy(dec.top_planar).to(self.dev)          # (P, n_top·Hp·Wp) int32
            self.disp = torch.from_numpy(dec.disp.astype(np.int64)).to(self.dev)
            self.offsets = torch.from_numpy(dec.offsets.astype(np.int64)).to(self.dev)
            self.key_of = torch.from_numpy(dec.key_of.astype(np.int64)).to(self.dev)

    def _pred_dcp(self, views: torch.Tensor, by: torch.Tensor, bx: torch.Tensor) -> torch.Tensor:
        """dcp prediction on the device, the integers of :func:`rlfc.disparity.predict_blocks`:
        (M,) requests → (M, B·B, P) int32."""
        d = self.d
        B, F, hp, wp = d.block_size, d.frac_bits, d.Hp, d.Wp
        k = self.key_of[views]
        disp = self.disp[k, by * d.nbx + bx]
        Y = ((by * B) << F) + disp * self.offsets[views, 0]                            # (M,)
        X = ((bx * B) << F) + disp * self.offsets[views, 1]
        ext = torch.arange(B + 1, device=self.dev)
        rows = ((Y >> F)[:, None] + ext).clamp(0, hp - 1)
        cols = ((X >> F)[:, None] + ext).clamp(0, wp - 1)
        idx = ((k * hp)[:, None, None] + rows[:, :, None]) * wp + cols[:, None, :]    # (M, B+1, B+1)
        win = self.top_planar[:, idx].permute(1, 2, 3, 0)                               # (M, B+1, B+1, P)
        if F == 0:
            out = win[:, :B, :B]
        else:
            s = 1 << F
            fy = (Y & (s - 1)).to(torch.int32)[:, None, None, None]
            fx = (X & (s - 1)).to(torch.int32)[:, None, None, None]
            h = win[:, :, :B] * (s - fx) + win[:, :, 1:] * fx                      # (M, B+1, B, P)
            out = (h[:, :B] * (s - fy) + h[:, 1:] * fy + (1 << (2 * F - 1))) >> (2 * F)
        return out.reshape(views.shape[0], B * B, d.P)

    def _unpack(self, starts: torch.Tensor, mode: int, n: int) -> torch.Tensor:
        """(S,) plane byte offsets → (S, n) int64 values of one mode."""
        if mode >= MODE_PLAIN:                       # plain k-bit fields (k <= 31: <= 5 bytes)
            k = mode - MODE_PLAIN
            pos = torch.arange(n, device=self.dev, dtype=torch.int64) * k
            w = _gather_word(self.buf, starts[:, None] + (pos >> 3)[None], 5)
            return (w >> (pos & 7)[None]) & ((1 << k) - 1)
        _, bits, trits, quints = RANGES[mode]
        if not (trits or quints):
            pos = torch.arange(n, device=self.dev, dtype=torch.int64) * bits
            w = _gather_word(self.buf, starts[:, None] + (pos >> 3)[None], 2)
            return (w >> (pos & 7)[None]) & ((1 << bits) - 1)
        from .bise import bit_length

        gpos, gmask, fields, group = _group_layout(bits, trits, n, bit_length(n, RANGE_VALUES[mode]))
        gp = torch.from_numpy(gpos).to(self.dev)
        gm = torch.from_numpy(gmask.astype(np.int64)).to(self.dev)
        word = _gather_word(self.buf, starts[:, None] + (gp >> 3)[None], 6)            # (S, G), <= 45 bits
        word = (word >> (gp & 7)[None]) & gm[None]
        code = torch.zeros_like(word)
        ms = [None] * group
        for kind, slot, off, width in fields:
            val = (word >> off) & ((1 << width) - 1)
            if kind == "m":
                ms[slot] = val
            else:
                code = code | (val << slot)
        digits = (self.trit if trits else self.quint)[code]                              # (S, G, group)
        if bits:
            digits = (digits << bits) | torch.stack(ms, -1)
        return digits.reshape(starts.shape[0], -1)[:, :n]

    def decode_blocks(self, views, by, bx, level: int = 0, to_numpy: bool = True):
        """Same contract as :meth:`RlfcDecoder.decode_blocks`; returns numpy (or a device tensor)."""
        d = self.d
        level = d._check_level(level)
        views, by, bx = d._requests(views, by, bx)
        M, B, P, n = views.size, d.block_size, d.P, d.block_size ** 2
        H = d.levels
        t = lambda a: torch.from_numpy(np.ascontiguousarray(a)).to(self.dev)  # noqa: E731
        if d.profile == "dcp":
            acc = self._pred_dcp(t(views), t(by), t(bx))                               # (M, n, P) int32
        else:
            acc = self.top[t(d.anc[H][views]), t(by), t(bx)]                            # (M, n, P) int32
        if H > level:
            levs = list(range(H - 1, level - 1, -1))
            g = np.concatenate([d.level_offset[lv] + d.anc[lv][views] for lv in levs])
            sel, is_raw, pay, modes, mins, pstart = d.store.locate(g, np.tile(by * d.nbx + bx, len(levs)))
            S = sel.size
            q = torch.zeros((S, P, n), dtype=torch.int64, device=self.dev)
            modes_t, mins_t, pstart_t = t(modes.astype(np.int64)), t(mins), t(pstart)
            nonraw = t(~is_raw)
            for m in np.unique(modes).tolist():
                kk, cc = torch.nonzero((modes_t == m) & nonraw[:, None], as_tuple=True)
                if kk.numel() == 0:
                    continue
                if m == MODE_CONST:
                    q[kk, cc] = mins_t[kk, cc][:, None]
                elif m < MODE_CONST or MODE_PLAIN < m < MODE_PLAIN + 32:
                    q[kk, cc] = self._unpack(pstart_t[kk, cc], m, n) + mins_t[kk, cc][:, None]
                else:
                    raise ChecksumError(f"rlfc block has invalid plane mode {m} (corrupt file)")
            a = q.abs() * self.q16[None, :, None]
            deq = torch.where(q < 0, -((a + 8) >> 4), (a + 8) >> 4).transpose(1, 2).to(torch.int32)   # (S, n, P)
            rawp = None
            if is_raw.any():
                ridx = t(np.flatnonzero(is_raw))
                nb = n * d.channels * d.dtype.itemsize
                byt = self.buf[t(pay[is_raw])[:, None] + torch.arange(nb, device=self.dev)[None]].to(torch.int64)
                smp = byt[:, 0::2] | (byt[:, 1::2] << 8) if d.dtype.itemsize == 2 else byt
                rawp = forward_int(smp.reshape(-1, n, d.channels)).to(torch.int32)
                deq[ridx] = 0
            sel_t, raw_t = t(sel), t(is_raw)
            lev_of = sel_t // M
            for i in range(len(levs)):                       # top-down over the tree height
                k = torch.nonzero(lev_of == i)[:, 0]
                req = sel_t[k] - i * M
                acc[req] += deq[k]
                if rawp is not None:
                    r = raw_t[k]
                    if bool(r.any()):
                        pos = torch.cumsum(raw_t.to(torch.int64), 0) - 1          # index into rawp
                        acc[req[r]] = rawp[pos[k[r]]]
        out = torch.clamp(inverse_int(acc.reshape(M, B, B, P)), 0, self.peak)
        if not to_numpy:
            return out
        return out.cpu().numpy().astype(d.dtype)
