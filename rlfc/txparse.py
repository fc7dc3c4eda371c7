"""Parsing the ``tx`` profile's block syntax (:mod:`rlfc.txsyntax`): many streams at once as
numpy lanes in lockstep (:func:`parse_lanes`), or one stream in plain Python
(:func:`rlfc.txparse_one.parse_one`, faster for a few streams); both give a :class:`Parsed` (the
tb modes and the nonzero levels, sparse) with the same integers. A stream that is malformed raises
:class:`formats.errors.FormatError`.
"""
from __future__ import annotations

from itertools import repeat

import numpy as np

from formats.errors import FormatError

from .rans import BACK_BITS, L as RANS_L, M as RANS_M, PROB_BITS, LaneDecoder, Tables
from .txsyntax import _BAND8_ARR, _MASK, ESC, MODE_SKIP, N_BUCKETS, N_CTX, N_MODES, ctx_esc, ctx_last, ctx_mag, ctx_mode

_BAND8_U32 = _BAND8_ARR.astype(np.uint32)
#: a magnitude parse finishes in plain Python once fewer lanes than this have symbols left
TAIL_LANES = 32
MAX_PARSE_SYMBOLS = 1 << 21   # magnitude symbols parsed together (~134 B each of temporaries: ~280 MB)


class Parsed:
    """Decoded syntax of S blocks of nt tbs and P planes: ``modes`` (S, nt) int64 and the
    nonzero quantized coefficients, sparse: ``index`` (K,) int64 into the flat (S, nt, P, 64)
    scan-order array (grouped by lane, tb and plane in ascending order; any order within one
    tb and plane) and ``values`` (K,) int64 signed. ``levels`` is the dense
    array, built on request."""

    def __init__(self, modes, index, values, planes: int):
        self.modes, self.index, self.values, self.P = modes, index, values, planes

    @classmethod
    def from_levels(cls, modes: np.ndarray, levels: np.ndarray) -> "Parsed":
        flat = levels.reshape(-1)
        idx = np.flatnonzero(flat)
        return cls(modes, idx, flat[idx], levels.shape[2])

    @property
    def levels(self) -> np.ndarray:
        S, nt = self.modes.shape
        out = np.zeros(S * nt * self.P * 64, np.int64)
        out[self.index] = self.values
        return out.reshape(S, nt, self.P, 64)

    def split(self, bounds) -> list:
        """Parsed of lanes [bounds[i], bounds[i+1]) each."""
        per = self.modes.shape[1] * self.P * 64
        cut = np.searchsorted(self.index, np.asarray(bounds, np.int64) * per)
        return [Parsed(self.modes[a:b], self.index[cut[i]:cut[i + 1]] - a * per, self.values[cut[i]:cut[i + 1]], self.P)
                for i, (a, b) in enumerate(zip(bounds[:-1], bounds[1:]))]

    def lane_bounds(self) -> np.ndarray:
        """(S + 1,) int64: lane i's coefficients are ``index[b[i]:b[i + 1]]`` (they are grouped by
        lane in ascending order)."""
        per = self.modes.shape[1] * self.P * 64
        return np.searchsorted(self.index, np.arange(self.modes.shape[0] + 1, dtype=np.int64) * per)

    def take(self, lanes: np.ndarray, bounds: np.ndarray | None = None) -> "Parsed":
        """Parsed of lanes ``lanes`` (int array, in its order; ``bounds``: :meth:`lane_bounds`,
        where the caller keeps it for several takes)."""
        per = self.modes.shape[1] * self.P * 64
        b = self.lane_bounds() if bounds is None else bounds
        lanes = np.asarray(lanes, np.int64)
        cnt = b[lanes + 1] - b[lanes]
        first = np.cumsum(cnt) - cnt
        src = np.repeat(b[lanes] - first, cnt) + np.arange(int(cnt.sum()), dtype=np.int64)
        index = self.index[src] - np.repeat((lanes - np.arange(lanes.size)) * per, cnt)
        return Parsed(self.modes[lanes], index, self.values[src], self.P)

    def reshape(self, lanes: int, nt: int) -> "Parsed":
        """The same coefficients seen as ``lanes`` lanes of ``nt`` tbs (a stream of several
        blocks in raster order = consecutive blocks)."""
        return Parsed(self.modes.reshape(lanes, nt), self.index, self.values, self.P)


def concat_parsed(parts: list) -> "Parsed":
    """One Parsed of the lanes of several, in order."""
    per = parts[0].modes.shape[1] * parts[0].P * 64
    off = np.cumsum([0] + [p.modes.shape[0] for p in parts[:-1]]) * per
    return Parsed(np.concatenate([p.modes for p in parts]), np.concatenate([p.index + o for p, o in zip(parts, off)]),
                  np.concatenate([p.values for p in parts]), parts[0].P)


def symbol_parts(per_lane: np.ndarray, budget: int) -> list:
    """Bounds [0, …, S] of runs of consecutive lanes whose symbol counts ``per_lane`` (S,) sum
    to at most ``budget`` each (a lane over it alone is a run of its own)."""
    bounds = [0]
    cs = np.cumsum(per_lane)
    while bounds[-1] < per_lane.size:
        a = bounds[-1]
        base = int(cs[a - 1]) if a else 0
        b = int(np.searchsorted(cs, base + budget, side="right"))
        bounds.append(max(b, a + 1))
    return bounds


def parse_lanes(buf: np.ndarray, starts: np.ndarray, ends: np.ndarray, tables: Tables, nt: int, pcs: np.ndarray,
                kind: np.ndarray, key: np.ndarray, name: str = "", max_symbols: int | None = None) -> Parsed:
    """Parse S streams at once (numpy lanes). ``buf`` holds the streams (8 bytes of slack after
    the last); stream i is ``buf[starts[i]:ends[i]]``.

    The streams' last positions say how many magnitude symbols follow (up to 64 per tb and
    plane, whatever the stream's length: a few bytes can claim them all). Where they sum to more
    than ``max_symbols`` (default :data:`MAX_PARSE_SYMBOLS`), the lanes are parsed in runs of at
    most that many, so a call's temporaries stay bounded whatever a file claims.

    Raises:
        FormatError: a stream that is malformed (bad symbol, overrun, wrong end state).
    """
    from .xp import NUMPY as xp

    S, P = starts.size, pcs.size
    modes = np.zeros((S, nt), np.int64)
    if S == 0:
        return Parsed(modes, np.zeros(0, np.int64), np.zeros(0, np.int64), P)
    dec = LaneDecoder(xp, buf, starts.astype(np.int64), tables)
    modes[...] = _modes(dec, tables, kind, nt)
    if (modes >= N_MODES).any():
        raise FormatError(f"{name}: tx block has an undefined tb mode")
    # last positions: per lane, those of its coded tbs' planes in order (t, then p)
    coded = modes != MODE_SKIP
    ct = np.flatnonzero(coded.reshape(-1))                              # lane·nt + t of coded tbs
    n_last = coded.sum(axis=1) * P
    at = (ct[:, None] * P + np.arange(P)).reshape(-1)                   # lane-major: (lane·nt + t)·P + p
    c_last = ctx_last(np.tile(pcs, ct.size), np.repeat(modes.reshape(-1)[ct], P), np.repeat(key[ct // nt], P))
    last = np.zeros((S, nt, P), np.int64)
    last.reshape(-1)[at] = _lasts(dec, tables, n_last, c_last)
    if (last > 64).any():
        raise FormatError(f"{name}: tx block has a last position past 64")
    # magnitudes: per lane, groups g = (lane, t, p) in order, each of length last; symbol j of a
    # group is at scan position last − 1 − j
    gl = last.reshape(S, nt * P)
    per_lane = gl.sum(axis=1)
    tot = int(per_lane.sum())
    budget = MAX_PARSE_SYMBOLS if max_symbols is None else max_symbols
    if tot > budget and S > 1:
        bounds = symbol_parts(per_lane, budget)
        return concat_parsed([parse_lanes(buf, starts[a:b], ends[a:b], tables, nt, pcs, kind[a:b], key[a:b], name,
                                          budget) for a, b in zip(bounds[:-1], bounds[1:])])
    lane_start = np.cumsum(per_lane) - per_lane
    flat_len = gl.reshape(-1)
    G = flat_len.size
    # (in place where they can be: every temporary of the symbols' size is pages faulted in)
    j = np.arange(tot, dtype=np.int32)
    j -= np.repeat((np.cumsum(flat_len) - flat_len).astype(np.int32), flat_len)
    index = np.repeat((np.arange(G) << 6) + flat_len - 1, flat_len)
    index -= j                                                              # g·64 + position: ascending
    g_pc = np.tile(pcs, G // P)                                             # per group: plane class, key
    g_ctx = ctx_mag(g_pc, 0, np.repeat(key, nt * P), 0)
    lane_end = lane_start + per_lane
    ctx1 = np.repeat(g_ctx.astype(np.uint32), flat_len)                     # (uint32 in place: the
    ctx1 += _BAND8_U32.take(index & 63)                                    # values are < 2^12)
    ctx1 += _J_FLAGS.take(j)                                               # + neighbour terms, flags
    sym = _magnitudes(dec, tables, S, per_lane, lane_start, ctx1)
    if tot and int(sym.max()) > ESC:
        raise FormatError(f"{name}: tx block has an undefined magnitude symbol")
    # escapes (symbol ESC: |c| >= ESC + first)
    esc = np.flatnonzero(sym == ESC)
    if esc.size:
        e_lane = np.searchsorted(lane_end, esc, side="right")             # each escape's lane
        ec = np.bincount(e_lane, minlength=S)
        es = np.cumsum(ec) - ec
        col = np.arange(esc.size) - es[e_lane]
        e_pc = g_pc[index[esc] >> 6]
        buckets = np.zeros(esc.size, np.int64)
        for k in range(int(ec.max())):
            sel = np.flatnonzero(col == k)
            buckets[sel] = dec.step(e_lane[sel], ctx_esc(e_pc[sel]))
        if (buckets >= N_BUCKETS).any() or (buckets > 40).any():
            raise FormatError(f"{name}: tx block has an undefined escape bucket")
    else:
        buckets = np.zeros(0, np.int64)
    # raw bits: signs then escape suffixes, per lane
    first = j == 0
    nz = sym > 0
    nz |= first
    sidx = np.flatnonzero(nz)
    nsign = np.diff(np.searchsorted(sidx, lane_end), prepend=0)    # per lane (a lane starts where the last ends)
    s_lane = np.repeat(np.arange(S), nsign)
    nsuf = np.bincount(e_lane, weights=buckets, minlength=S).astype(np.int64) if esc.size else np.zeros(S, np.int64)
    nbits = nsign + nsuf
    kb = np.minimum(nbits, BACK_BITS)
    raw_start = ends - (nbits - kb + 7) // 8
    from .rans import STATE_BYTES

    ok = dec.check(raw_start, kb) & (raw_start >= starts + STATE_BYTES)
    if not ok.all():
        raise FormatError(f"{name}: tx block stream is malformed (its symbols do not end where its raw bits start)")
    raw = _RawBits(buf, raw_start, ends, dec.back(), kb)
    sbit = raw.signs(nsign, s_lane)
    vals = sym[sidx].astype(np.int64)
    vals += first[sidx]
    if esc.size:
        eoff = nsign[e_lane] + (np.cumsum(buckets) - buckets) - (np.cumsum(nsuf) - nsuf)[e_lane]
        suffix = np.zeros(esc.size, np.int64)
        for b in range(int(buckets.max(initial=0))):
            m = buckets > b
            suffix[m] |= raw.at(e_lane[m], eoff[m] + b).astype(np.int64) << b
        vals[np.searchsorted(sidx, esc)] = ESC + first[esc] + ((1 << buckets) - 1) + suffix   # (escapes are
    np.negative(vals, out=vals, where=sbit.view(bool))                                       # nonzero: in sidx)
    return Parsed(modes, index[sidx], vals, P)


class _RawBits:
    """Each lane's raw bits (its signs, then its escapes' suffixes): bits below ``kb`` from the
    start state's R (``back``), the others stored LSB-first from byte ``raw_start`` to ``ends``
    (the callers' checks having put them inside the buffer). Every lane's stored bytes are
    unpacked once; a bit is then one look-up (arrays per lane: raw_start, ends, back, kb)."""

    def __init__(self, buf, raw_start, ends, back, kb):
        nbytes = ends - raw_start
        cb = np.cumsum(nbytes) - nbytes                                 # each lane's first unpacked byte
        nb = int(nbytes.sum())
        # (no stored byte anywhere: every bit is below its lane's kb, read from back)
        self.bits = np.unpackbits(buf[np.repeat(raw_start - cb, nbytes) + np.arange(nb)], bitorder="little") \
            if nb else np.zeros(1, np.uint8)
        self.first = 8 * cb - kb                                        # raw bit i (>= kb) of lane L: bits[first[L] + i]
        self.back, self.kb = back, kb

    def at(self, lane, off) -> np.ndarray:
        """Raw bit ``off`` of lane ``lane`` (arrays), uint8."""
        out = self.bits.take(self.first[lane] + off, mode="clip")      # (those below kb: replaced)
        low = np.flatnonzero(off < self.kb[lane])
        if low.size:
            out[low] = (self.back[lane[low]] >> off[low]) & 1
        return out

    def signs(self, nsign, s_lane) -> np.ndarray:
        """Raw bits 0..nsign − 1 of every lane, in lane order (``s_lane`` (K,): their lanes), uint8:
        :meth:`at` of them in fewer passes (their offsets are consecutive; at most BACK_BITS a
        lane from back)."""
        cs = np.cumsum(nsign) - nsign                                   # each lane's first sign
        at = np.arange(s_lane.size, dtype=np.int64)
        at += (self.first - cs)[s_lane]
        out = self.bits.take(at, mode="clip")                           # (those below kb: replaced)
        nlow = np.minimum(self.kb, nsign)
        if nlow.any():
            lanes = np.repeat(np.arange(nsign.size), nlow)
            off = np.arange(int(nlow.sum())) - np.repeat(np.cumsum(nlow) - nlow, nlow)   # bit within the lane
            out[cs[lanes] + off] = (self.back[lanes] >> off) & 1
        return out


def _magnitudes(dec: LaneDecoder, tables: Tables, S: int, per_lane, lane_start, ctx1) -> np.ndarray:
    """The magnitude symbols of every lane (flat, lane-major, uint8), decoded in steps over the lanes
    that still have symbols (:func:`_ragged`).

    ``ctx1`` (flat, lane-major, uint32): each symbol's context without its neighbour count, plus
    :data:`_J_FLAGS` of its index j in its group. A group's first symbol always counts as a
    nonzero neighbour, so the symbols after it (j = 1, 2) get that +1 up front and look back only
    at symbols of their group past the first (j >= 2, 3): a neighbour adds min(its symbol, g)
    with g = 1 where it counts, else 0; g of the previous symbol is bit 16 of ``ctx1``, of the
    one before it bit 17 (packed, the symbols are put in step-major order in one scatter).
    """
    plan = _Plan(per_lane, lane_start)
    sm = plan.sm
    c1 = np.empty(ctx1.size, np.uint32)
    c1[sm] = ctx1
    g2 = c1 >> _U17                                                    # (contiguous passes from here)
    g1 = c1 >> _U16
    g1 &= _U1
    c1 &= _U16M
    return _ragged(dec, tables, plan, c1, g1, g2).astype(np.uint8)[sm]


#: per index j of a magnitude symbol in its group (< 64): what its context adds, +1 where j >= 1
#: and +1 more where j is 1 or 2 (the group's first symbol, a nonzero neighbour), and the flags of
#: :func:`_magnitudes`: bit 16 where j >= 2 (the previous symbol counts), bit 17 where j >= 3
_J_FLAGS = np.array([0, 2, 2 | 1 << 16] + [1 | 1 << 16 | 1 << 17] * 61, np.uint32)
assert N_CTX < 1 << 16                                                 # (contexts below the flags)


def _lasts(dec: LaneDecoder, tables: Tables, n: np.ndarray, ctx: np.ndarray) -> np.ndarray:
    """``n[i]`` symbols of each lane i with contexts ``ctx`` (flat, lane-major; no neighbours),
    decoded by :func:`_ragged`: (Σn,) uint32, lane-major."""
    plan = _Plan(n, np.cumsum(n) - n)
    c1 = np.empty(ctx.size, np.uint32)
    c1[plan.sm] = ctx
    return _ragged(dec, tables, plan, c1, None, None)[plan.sm]


def _modes(dec: LaneDecoder, tables: Tables, kind: np.ndarray, nt: int) -> np.ndarray:
    """The nt tb modes of every lane, (S, nt) uint32: each in the context of the lane's kind and
    previous mode (3 before the first), in the steps of :func:`_step`."""
    S = kind.size
    out = np.empty((nt, S), np.uint32)
    x, p = dec.x.astype(np.uint32), dec.ptr.astype(np.intp)
    pair, lo = _pairs(dec, p, nt)
    base = (ctx_mode(np.asarray(kind, np.int64), 0)).astype(np.uint32)
    prev = np.full(S, 3, np.uint32)
    c, a, b = np.empty(S, np.uint32), np.empty(S, np.uint32), np.empty(S, np.uint32)
    tab = mag_words(tables)
    for t in range(nt):
        np.add(base, prev, out=c)
        c <<= _U12
        _step(tab, pair, c, x, p, a, b, out[t])
        prev = out[t]
    p += lo
    dec.x[:], dec.ptr[:] = x, p
    return out.T


class _Plan:
    """Lanes of ``per_lane`` symbols each (lane-major from ``lane_start``) in step-major order:
    lanes ranked by their number of symbols (longest first), so that the lanes active at step k
    are ranks [0, m_k) and symbol k of rank r sits at offs[k] + r (``sm``: each lane-major
    symbol's step-major place)."""

    def __init__(self, per_lane: np.ndarray, lane_start: np.ndarray):
        S, tot = per_lane.size, int(per_lane.sum())
        self.order = order = np.argsort(-per_lane, kind="stable")
        rank = np.empty(S, np.int64)
        rank[order] = np.arange(S)
        self.lens = lens = per_lane[order]
        self.K = K = int(lens[0]) if S else 0
        self.cnt = cnt = np.searchsorted(-lens, -np.arange(K), side="left")   # lanes with more than k symbols
        self.offs = offs = np.cumsum(cnt) - cnt
        k = np.arange(tot)                                             # each symbol's index in its lane
        k -= np.repeat(lane_start, per_lane)                           # (in place: fewer fresh pages)
        self.sm = offs.take(k)
        self.sm += np.repeat(rank, per_lane)


def _pairs(dec: LaneDecoder, p_all: np.ndarray, K: int) -> tuple:
    """(pair, lo): the bytes ``K`` steps of lanes at pointers ``p_all`` can read (at most two a
    symbol), as big-endian pairs (uint32: bytes p, p + 1) from the lowest pointer lo on, and
    zeros past the buffer (whose last bytes are slack; the end check refuses a stream read
    there). ``p_all`` is made relative to lo (the caller adds it back)."""
    buf, top = dec.buf, dec.top
    lo, pmax = (int(p_all.min()), int(p_all.max())) if p_all.size else (0, 0)
    lo = min(lo, top + 1)
    hi = max(min(pmax + 2 * K + 2, top + 1), lo)
    bufp = np.concatenate([buf[lo:hi], np.zeros(pmax + 2 * K + 4 - hi, np.uint8)])
    pair = bufp[:-1].astype(np.uint32)
    pair <<= 8
    pair |= bufp[1:]
    p_all -= lo
    return pair, lo


def _step(tab, pair, c, x, p, a, b, out) -> None:
    """One rANS step of lanes in states ``x`` (uint32) at pointers ``p`` (intp, into ``pair``)
    with contexts ``c`` (uint32, shifted to their table rows; the slot is or-ed in): the
    symbols to ``out``, x and p updated in place; ``a``, ``b``: uint32 scratch of the lanes' size.

    One :func:`mag_words` look-up and the rANS update, then the renormalization without a
    branch: n = [x < L] + [x < L / 256] bytes in (the borrows of two uint32 subtractions), read
    as one pair, x = x << 8n | pair >> (16 − 8n). Every operation has uint32 operands of one
    type: numpy's per-call cost, not the lanes, bounds a step, and a Python scalar operand or a
    mixed-type cast costs as much as the work."""
    np.bitwise_and(x, _UMASK, out=a)
    c |= a
    w = tab.take(c)                                                    # (c is in range)
    np.right_shift(w, _U25, out=out)
    np.right_shift(w, _U12, out=b)                                     # x = freq·(x >> 12) + slot − cum
    b &= _UFREQ
    np.right_shift(x, _U12, out=a)
    b *= a
    np.bitwise_and(w, _USLOT, out=a)
    np.add(b, a, out=x)
    np.subtract(x, _UL, out=a)                                         # n = [x < L] + [x < L / 256]
    a >>= _U31
    np.subtract(x, _UL8, out=b)
    b >>= _U31
    a += b
    v = pair.take(p)
    np.add(p, a, out=p, casting="unsafe")
    a <<= _U3
    x <<= a
    np.subtract(_U16, a, out=b)
    v >>= b
    x |= v


def _ragged(dec: LaneDecoder, tables: Tables, plan: _Plan, c1, g1, g2) -> np.ndarray:
    """The symbols (step-major, uint32) of lanes laid out by ``plan``, contexts ``c1`` (step-major,
    unshifted), each plus min(previous symbol, g1) + min(the one before, g2) (step-major; None:
    no neighbours), one :func:`_step` per symbol index over the lanes still active (contiguous
    slices: the lanes' states are kept in rank order), the last few lanes in plain Python
    (:data:`TAIL_LANES`)."""
    order, lens, K, cnt, offs = plan.order, plan.lens, plan.K, plan.cnt, plan.offs
    S = order.size
    syms = np.empty(c1.size, np.uint32)
    syms.fill(0)                                  # (its pages touched once here, not a step at a time)
    tab = mag_words(tables)
    x_all, p_all = dec.x[order].astype(np.uint32), dec.ptr[order].astype(np.intp)
    pair, lo = _pairs(dec, p_all, K)
    ta, tb = np.empty(S, np.uint32), np.empty(S, np.uint32)
    offl = offs.tolist()
    for k, (o, m) in enumerate(zip(offl, cnt.tolist())):
        if m < TAIL_LANES:                                             # few lanes left: plain Python
            p_all += lo
            _ragged_tail(k, m, offl, lens, c1, g1, g2, syms, x_all, p_all, dec.buf, dec.top, tables)
            p_all -= lo
            break
        c, a = c1[o:o + m], ta[:m]
        if g1 is not None and k >= 1:
            o1 = offl[k - 1]
            np.minimum(syms[o1:o1 + m], g1[o:o + m], out=a)
            c += a
            if k >= 2:
                o2 = offl[k - 2]
                np.minimum(syms[o2:o2 + m], g2[o:o + m], out=a)
                c += a
        c <<= _U12
        _step(tab, pair, c, x_all[:m], p_all[:m], a, tb[:m], syms[o:o + m])
    p_all += lo
    dec.x[order], dec.ptr[order] = x_all, p_all
    return syms


def _ragged_tail(k, m, offl, lens, c1, g1, g2, syms, x_all, p_all, buf, top, tables) -> None:
    """:func:`_ragged` from step ``k`` on, where only ranks [0, m) have symbols left: each
    lane to its end in plain Python (the same integers; a numpy step costs ~25 calls whatever
    the lanes), its contexts gathered first (numpy, a lane at a time) and its symbols stored
    after. Reads past the buffer are clamped as in the numpy steps (the caller's end check
    refuses such a stream)."""
    offs = np.asarray(offl[k:], np.int64)
    tab = memoryview(mag_words(tables))
    data = memoryview(buf)
    for r in range(m):
        x, p = int(x_all[r]), int(p_all[r])
        n1 = bool(syms[offl[k - 1] + r]) if k >= 1 else False       # the lane's two previous symbols
        n2 = bool(syms[offl[k - 2] + r]) if k >= 2 else False
        at = offs[:int(lens[r]) - k] + r                             # the lane's places, step-major
        out = []
        put = out.append
        none = repeat(0)                                             # (no neighbours: last positions)
        for b, u, v in zip((c1[at] << PROB_BITS).tolist(), none if g1 is None else (g1[at] << PROB_BITS).tolist(),
                           none if g2 is None else (g2[at] << PROB_BITS).tolist()):
            w = tab[(b + (u if n1 else 0) + (v if n2 else 0)) | (x & _MASK)]
            x = ((w >> 12) & 0x1FFF) * (x >> PROB_BITS) + (w & 0xFFF)
            if x < RANS_L:                 # at most two bytes, as the numpy steps (x >= 8 after a
                x = (x << 8) | data[p if p < top else top]   # step of a state >= RANS_L; a damaged
                p += 1                     # stream's 0 state stays 0 instead of reading forever)
                if x < RANS_L:
                    x = (x << 8) | data[p if p < top else top]
                    p += 1
            s = w >> 25
            put(s)
            n2, n1 = n1, s > 0
        syms[at] = out
        x_all[r], p_all[r] = x, p


def _u32(v: int) -> np.ndarray:
    return np.array(v, np.uint32)


# the magnitude steps' operands: 0-d uint32 arrays (a Python int operand costs a step ~1 µs a call)
_U1, _U3, _U12, _U16, _U17, _U25, _U31 = _u32(1), _u32(3), _u32(12), _u32(16), _u32(17), _u32(25), _u32(31)
_U16M = _u32(0xFFFF)
_UMASK, _UFREQ, _USLOT, _UL, _UL8 = _u32(_MASK), _u32(0x1FFF), _u32(0xFFF), _u32(RANS_L), _u32(RANS_L >> 8)


def mag_words(tables: Tables) -> np.ndarray:
    """(C·M,) uint32 per context and slot: (slot − cum) | freq << 12 | symbol << 25 (the layout of
    the numpy magnitude steps: the symbol's test for zero one comparison); alphabets up to 128
    symbols. Cached on the tables."""
    got = getattr(tables, "_mag_words", None)
    if got is None:
        C, A = tables.freq.shape
        if A > 128:
            raise ValueError("magnitude words hold alphabets of at most 128 symbols")
        f = tables.freq.reshape(-1).astype(np.int64)
        # as slot_words: each symbol's word minus its flat start, repeated over its slots, plus
        # the flat slot index g (uint32 arithmetic wraps; the result, g − start < freq, does not)
        start = (np.arange(C, dtype=np.int64)[:, None] * RANS_M + tables.cum[:, :A]).reshape(-1)
        word = ((np.tile(np.arange(A, dtype=np.int64), C) << 25) | (f << 12)) - start
        got = np.repeat((word & 0xFFFFFFFF).astype(np.uint32), f)
        got += np.arange(C * RANS_M, dtype=np.uint32)
        tables._mag_words = got
    return got


def slot_words(tables: Tables) -> np.ndarray:
    """(C·M,) uint32 per context and slot: symbol | freq << 7 | (slot − cum) << 20, so one
    look-up serves a decode step (x = freq·(x >> n) + slot − cum); alphabets up to 128 symbols.
    Cached on the tables."""
    got = getattr(tables, "_slot_words", None)
    if got is None:
        C, A = tables.freq.shape
        if A > 128:
            raise ValueError("slot words hold alphabets of at most 128 symbols")
        f = tables.freq.reshape(-1).astype(np.int64)       # (each row sums to M: Tables checks it)
        # slot − cum = g − start, g the flat slot index (context·M + slot) and start = context·M
        # + cum: each symbol's word with −start << 20 (mod 2^32) repeated over its slots, then
        # g << 20 added in uint32 (wrapping): two passes over the C·M words (0.6 ms, not 7)
        start = (np.arange(C, dtype=np.int64)[:, None] * RANS_M + tables.cum[:, :A]).reshape(-1)
        word = (np.tile(np.arange(A, dtype=np.int64), C) | (f << 7)) + ((-start << 20) & 0xFFFFFFFF)
        got = np.repeat((word & 0xFFFFFFFF).astype(np.uint32), f)
        got += np.arange(C * RANS_M, dtype=np.uint32) << np.uint32(20)
        tables._slot_words = got
    return got
