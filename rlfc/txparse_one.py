"""One ``tx`` block stream parsed in plain Python (:func:`parse_one`): the same
:class:`rlfc.txparse.Parsed` as :func:`rlfc.txparse.parse_lanes`, faster where only a few
streams are parsed (a single random-access request, key rows of a few streams).
"""
from __future__ import annotations

import numpy as np

from formats.errors import FormatError

from .rans import BACK_BITS, L as RANS_L, PROB_BITS, STATE_BYTES, Tables, scalar_step, scalar_tables
from .txparse import Parsed
from .txsyntax import _BAND8, _MASK, CTX_ESC, CTX_LAST, CTX_MAG, CTX_MODE, ESC, MODE_INTRA, MODE_SKIP, N_BANDS, \
    N_BUCKETS, N_MODES, N_PC


def parse_one(data: bytes, tables: Tables, nt: int, pcs, kind: int, key: int) -> Parsed:
    """One stream in plain Python (the same results as :func:`parse_lanes`; faster than lanes
    for a few streams).

    Every rANS step is inlined on locals (the tables' per-context slot → symbol bytes and
    frequency and cum lists: Python ints below 2^30, CPython's one-digit ints); each nonzero
    coefficient is one Python int, ``(g·64 + position) << 8 | magnitude`` (g = tb·P + plane;
    an escape's magnitude symbol, the rest of it added afterwards), and the signs are bits
    0..K−1 of the raw bits. ``pcs``: the planes' classes (a list of ints is used as it is)."""
    pcl = pcs if type(pcs) is list else [int(v) for v in pcs]
    P = len(pcl)
    if len(data) < STATE_BYTES:
        raise FormatError(f"rANS stream shorter than its {STATE_BYTES}-byte state")
    slot_t, freq_t, cum_t = scalar_tables(tables)
    x = int.from_bytes(data[:STATE_BYTES], "little")
    ptr = STATE_BYTES
    modes, lasts = [], []            # lasts: (g, last) of each coded (tb, plane), in order
    esc = []                         # the places in words of escape symbols (and bad ones)
    words = []
    put = words.append
    try:
        ctx = CTX_MODE + kind * 4 + 3
        for _ in range(nt):                          # (the rANS step inlined, as for magnitudes)
            sl = x & _MASK
            s = slot_t[ctx][sl]
            x = freq_t[ctx][s] * (x >> PROB_BITS) + sl - cum_t[ctx][s]
            while x < RANS_L:
                x = (x << 8) | data[ptr]
                ptr += 1
            if s >= N_MODES:
                raise FormatError("tx block has an undefined tb mode")
            modes.append(s)
            ctx = CTX_MODE + kind * 4 + s
        lrows = _LAST_CTX[key]
        for t in range(nt):
            mt = modes[t]
            if mt != MODE_SKIP:
                row = lrows[mt == MODE_INTRA]
                for p in range(P):
                    ctx = row[pcl[p]]
                    sl = x & _MASK
                    v = slot_t[ctx][sl]
                    x = freq_t[ctx][v] * (x >> PROB_BITS) + sl - cum_t[ctx][v]
                    while x < RANS_L:
                        x = (x << 8) | data[ptr]
                        ptr += 1
                    if v > 64:
                        raise FormatError("tx block has a last position past 64")
                    if v:
                        lasts.append((t * P + p, v))
        for g, n in lasts:
            bb = _MAG_ROWS[pcl[g % P], key]          # per position: context of the first symbol
            g8 = g << 14                             # (g·64) << 8
            pos = n - 1
            ctx = bb[pos]
            sl = x & _MASK
            s = slot_t[ctx][sl]
            x = freq_t[ctx][s] * (x >> PROB_BITS) + sl - cum_t[ctx][s]
            while x < RANS_L:
                x = (x << 8) | data[ptr]
                ptr += 1
            if s >= ESC:
                esc.append((len(words), s))
            put(g8 | (pos << 8) | (s + 1))           # the first is nonzero: its magnitude is s + 1
            nb, n1 = 2, 1                            # 1 + nonzero among the two previous; the previous
            for pos in range(n - 2, -1, -1):
                ctx = bb[pos] + nb
                sl = x & _MASK
                s = slot_t[ctx][sl]
                x = freq_t[ctx][s] * (x >> PROB_BITS) + sl - cum_t[ctx][s]
                while x < RANS_L:
                    x = (x << 8) | data[ptr]
                    ptr += 1
                if s:                                # zeros carry no sign, escape or level
                    if s >= ESC:
                        esc.append((len(words), s))
                    put(g8 | (pos << 8) | s)
                    nb, n1 = 2 + n1, 1
                else:
                    nb, n1 = 1 + n1, 0
        buckets = []
        for i, s in esc:
            if s > ESC:
                raise FormatError("tx block has an undefined magnitude symbol")
            k, x, ptr = scalar_step(slot_t, freq_t, cum_t, CTX_ESC + pcl[(words[i] >> 14) % P], x, ptr, data)
            if k >= N_BUCKETS:
                raise FormatError("tx block has an undefined escape bucket")
            buckets.append(k)
    except IndexError:
        raise FormatError("rANS stream reads past its end") from None
    nsign = len(words)                               # every coefficient kept is nonzero
    nbits = nsign + sum(buckets)
    kb = min(nbits, BACK_BITS)
    raw_start = len(data) - (nbits - kb + 7) // 8
    if not (0 <= x - RANS_L < (1 << kb) and ptr == raw_start):
        raise FormatError("tx block stream is malformed (its symbols do not end where its raw bits start)")
    raw = (x - RANS_L) | (int.from_bytes(data[raw_start:], "little") << kb)
    if nsign <= SMALL_SIGNS:                         # few coefficients: Python ints, then two arrays
        mag = [wd & 255 for wd in words]
        bit = nsign
        for (i, _), k in zip(esc, buckets):          # |c| = ESC + first + 2^k − 1 + k raw bits
            mag[i] += ((1 << k) - 1) + ((raw >> bit) & ((1 << k) - 1))
            bit += k
        for i in range(nsign):
            if (raw >> i) & 1:
                mag[i] = -mag[i]
        return Parsed(np.array([modes], np.int64), np.array([wd >> 8 for wd in words], np.int64),
                      np.array(mag, np.int64), P)
    w = np.array(words, np.int64)
    index, mag = w >> 8, w & 255
    bit = nsign
    for (i, _), k in zip(esc, buckets):
        mag[i] += ((1 << k) - 1) + ((raw >> bit) & ((1 << k) - 1))
        bit += k
    nb = (nsign + 7) >> 3
    signs = np.unpackbits(np.frombuffer((raw & ((1 << (8 * nb)) - 1)).to_bytes(nb, "little"), np.uint8),
                          count=nsign, bitorder="little")
    np.negative(mag, out=mag, where=signs.view(bool))
    return Parsed(np.array([modes], np.int64), index, mag, P)


#: coefficients up to which :func:`parse_one` signs them in Python ints (above: numpy)
SMALL_SIGNS = 48


#: per (plane class, key), per scan position: the context of a (tb, plane)'s first magnitude
#: symbol; the symbols after it add 1 + their count of nonzero neighbours
_MAG_ROWS = {(pc, key): [CTX_MAG + pc * N_BANDS * 8 + key * 4 + b for b in _BAND8]
             for pc in range(N_PC) for key in (0, 1)}
#: per key, mode class (intra?) and plane class: the context of a (tb, plane)'s last position
_LAST_CTX = [[[CTX_LAST + (pc * 2 + ci) * 2 + key for pc in range(N_PC)] for ci in (0, 1)] for key in (0, 1)]
