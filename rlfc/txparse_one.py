"""One ``tx`` block stream parsed in plain Python (:func:`parse_one`): the same
:class:`rlfc.txparse.Parsed` as :func:`rlfc.txparse.parse_lanes`, faster where only a few
streams are parsed (a single random-access request, key rows of a few streams).
"""
from __future__ import annotations

import numpy as np

from formats.errors import FormatError

from .transform import COEF_MAX
from .rans import BACK_BITS, L as RANS_L, PROB_BITS, STATE_BYTES, Tables, scalar_step, scalar_tables
from .txparse import Parsed
from .txsyntax import _BAND8, _MASK, CTX_ESC, CTX_LAST, CTX_MAG, CTX_MODE, ESC, MODE_INTRA, MODE_SKIP, N_BANDS, \
    N_BUCKETS, N_MODES, N_PC


def parse_one(data: bytes, tables: Tables, nt: int, pcs, kind: int, key: int) -> Parsed:
    """One stream in plain Python (the same results as :func:`parse_lanes`; faster than lanes
    for a few streams). ``pcs``: the planes' classes (a list of ints is used as it is)."""
    pcl = pcs if type(pcs) is list else [int(v) for v in pcs]
    return _parsed(*_words(data, tables, nt, pcl, kind, key), len(pcl))


def _parsed(modes: list, words: list, esc: list, buckets: list, raw: int, P: int) -> Parsed:
    """:func:`parse_one`'s :class:`Parsed` of :func:`_words`' symbols."""
    nsign = len(words)                               # every coefficient kept is nonzero
    if nsign <= SMALL_SIGNS:                         # few coefficients: Python ints, then two arrays
        mag = [wd & 255 for wd in words]
        _add_escapes(mag, esc, buckets, raw, nsign)
        for i in range(nsign):
            if (raw >> i) & 1:
                mag[i] = -mag[i]
        return Parsed(np.array([modes], np.int64), np.array([wd >> 8 for wd in words], np.int64),
                      np.array(mag, np.int64), P)
    w = np.array(words, np.int64)
    index, mag = w >> 8, w & 255
    _add_escapes(mag, esc, buckets, raw, nsign)
    np.negative(mag, out=mag, where=_sign_bits(raw, nsign))
    return Parsed(np.array([modes], np.int64), index, mag, P)


def parse_one_rows(data: bytes, tables: Tables, nt: int, pcl: list, kind: int, key: int, rows: tuple
                   ) -> tuple[list, object, object]:
    """One stream parsed as :func:`parse_one` and dequantized for a single request's residual:
    (the tbs' modes as a list, each nonzero coefficient's place, its dequantized value clipped to
    ±COEF_MAX), without the :class:`Parsed` in between (the same numbers as
    :func:`rlfc.kernels.dequantize` of ``Parsed.values`` at ``rows``' steps, clipped). ``rows``:
    (per index g·64 + scan position: its place, as a list and an int64 array; per g = tb·P +
    plane: its step in 1/16, as a list and an int64 array). Places and values are lists where
    the coefficients are few (:data:`SMALL_SIGNS`), int64 arrays above. Where a tb is
    intra-coded (the planes' path decodes it): (the modes, the stream's :class:`Parsed`, None)."""
    modes, words, esc, buckets, raw = _words(data, tables, nt, pcl, kind, key)
    if MODE_INTRA in modes:
        return modes, _parsed(modes, words, esc, buckets, raw, len(pcl)), None
    place, q16, place_a, q16_a = rows
    nsign = len(words)
    if nsign <= SMALL_SIGNS:
        mag = [wd & 255 for wd in words]
        _add_escapes(mag, esc, buckets, raw, nsign)
        vals = []
        put = vals.append
        for i in range(nsign):                       # sign(q)·((|q|·q16 + 8) >> 4), clipped
            d = (mag[i] * q16[words[i] >> 14] + 8) >> 4
            if d > COEF_MAX:
                d = COEF_MAX
            put(-d if (raw >> i) & 1 else d)
        return modes, [place[wd >> 8] for wd in words], vals
    w = np.array(words, np.int64)
    mag = w & 255
    _add_escapes(mag, esc, buckets, raw, nsign)
    mag *= q16_a[w >> 14]
    mag += 8
    mag >>= 4
    np.minimum(mag, COEF_MAX, out=mag)
    np.negative(mag, out=mag, where=_sign_bits(raw, nsign))
    w >>= 8
    return modes, place_a[w], mag


def _add_escapes(mag, esc: list, buckets: list, raw: int, nsign: int) -> None:
    """The escapes' magnitudes completed in place (a list or an array): |c| = ESC + first +
    2^k − 1 + k raw bits (the raw bits after the ``nsign`` signs)."""
    bit = nsign
    for (i, _), k in zip(esc, buckets):
        mag[i] += ((1 << k) - 1) + ((raw >> bit) & ((1 << k) - 1))
        bit += k


def _sign_bits(raw: int, nsign: int) -> np.ndarray:
    """Bits 0..nsign−1 of ``raw`` as a bool array (the coefficients' signs: set = negative)."""
    nb = (nsign + 7) >> 3
    return np.unpackbits(np.frombuffer((raw & ((1 << (8 * nb)) - 1)).to_bytes(nb, "little"), np.uint8),
                         count=nsign, bitorder="little").view(bool)


def _words(data: bytes, tables: Tables, nt: int, pcl: list, kind: int, key: int) -> tuple:
    """A stream's symbols in plain Python: (modes list, words, escapes, buckets, raw bits).

    Every rANS step is inlined on locals (the tables' per-context slot → symbol bytes and
    frequency and cum lists: Python ints below 2^30, CPython's one-digit ints); each nonzero
    coefficient is one Python int, ``(g·64 + position) << 8 | magnitude`` (g = tb·P + plane;
    an escape's magnitude symbol, the rest of it added afterwards: ``escapes`` holds its place
    in words and its symbol, ``buckets`` its bucket), and the signs are bits 0..K−1 of the raw
    bits (K = len(words)), the escapes' extra bits after them."""
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
    return modes, words, esc, buckets, (x - RANS_L) | (int.from_bytes(data[raw_start:], "little") << kb)


#: coefficients up to which :func:`parse_one` signs them in Python ints (above: numpy)
SMALL_SIGNS = 48


#: per (plane class, key), per scan position: the context of a (tb, plane)'s first magnitude
#: symbol; the symbols after it add 1 + their count of nonzero neighbours
_MAG_ROWS = {(pc, key): [CTX_MAG + pc * N_BANDS * 8 + key * 4 + b for b in _BAND8]
             for pc in range(N_PC) for key in (0, 1)}
#: per key, mode class (intra?) and plane class: the context of a (tb, plane)'s last position
_LAST_CTX = [[[CTX_LAST + (pc * 2 + ci) * 2 + key for pc in range(N_PC)] for ci in (0, 1)] for key in (0, 1)]
