"""Syntax of one coded random-access block of the ``tx`` profile: symbols, contexts, raw bits.

A block of B×B pixels holds nt = (B/8)² transform blocks ("tbs", raster order) of P planes.
Its stream (see :mod:`rlfc.rans`) holds, in decode order:

1. ``mode`` of each tb: 0 skip (prediction only), 1 residual (prediction + coefficients),
   2 intra (flat prediction + coefficients). Context: view kind (0 predicted from references,
   1 intra view) × 4 + previous tb's mode in this block (3 for the first tb).
2. ``last`` of each coded tb and plane, in (tb, plane) order: 1 + the scan position of the
   last nonzero coefficient, 0 = none. Context: plane class × tb mode class × key.
3. Magnitudes of each (tb, plane) with last > 0, scan positions last−1 down to 0: symbol
   min(|c|, 15) — min(|c| − 1, 15) at position last−1, which is nonzero. Context: plane
   class × band of the scan position × key × (first | 0, 1, 2 nonzeros among the two
   previous magnitudes of the same tb and plane).
4. Escapes: for each magnitude symbol 15, in order, a bucket k with r = |c| − 15 (−16 at
   position last−1) in [2^k − 1, 2^(k+1) − 1). Context: plane class.

Raw bits: a sign bit (1 = negative) per nonzero coefficient in magnitude order, then the k
low bits of r − (2^k − 1) of each escape, in order; nbits in all. The first b = min(nbits, 15)
ride in the rANS start state (R = bits 0..b−1, LSB first; :mod:`rlfc.rans`), the rest are
stored LSB-first from byte ``end − ceil((nbits − b)/8)`` to the end of the stream. The rANS
part ends exactly where the stored raw bits start.

Plane classes: 0 = Y (or grey), 1 = Co/Cg, 2 = alpha. Scan: zig-zag (``rlfc.transform.ZIGZAG``)
for transformed planes, raster for transform-bypassed planes (alpha, lossless).
On-wire constants; do not reorder.
"""
from __future__ import annotations

import numpy as np

from formats.errors import FormatError

from .rans import BACK_BITS, M as RANS_M, Tables, encode_lanes

N_MODES = 3
MODE_SKIP, MODE_RES, MODE_INTRA = 0, 1, 2
ESC = 15
N_BUCKETS = 24
#: band of each scan position 0..63
BAND = np.array([0] + [1] * 2 + [2] * 3 + [3] * 4 + [4] * 11 + [5] * 43, dtype=np.int64)
N_BANDS = 6
_BAND8 = [8 * int(b) for b in BAND]      # band·8: the band's offset among magnitude contexts
_BAND8_ARR = np.array(_BAND8, np.int64)
N_PC = 3          # plane classes
_MASK = RANS_M - 1

# context layout: one table set, contexts numbered by kind of symbol
CTX_MODE = 0                                    # 2 kinds × 4 previous modes
CTX_LAST = CTX_MODE + 8                         # 3 plane classes × 2 mode classes × 2 key
CTX_MAG = CTX_LAST + N_PC * 2 * 2               # 3 pc × 6 bands × 2 key × 4 (first, nbr 0..2)
CTX_ESC = CTX_MAG + N_PC * N_BANDS * 2 * 4      # 3 pc
N_CTX = CTX_ESC + N_PC
ALPHABET = 65
_BAND8_65 = _BAND8_ARR * ALPHABET        # band·8·ALPHABET: a magnitude's band in flat count indices


def plane_classes(planes: int) -> np.ndarray:
    """(P,) plane class of each plane: grey / grey+alpha / YCoCg / YCoCg+alpha."""
    return {1: np.array([0]), 2: np.array([0, 2]), 3: np.array([0, 1, 1]), 4: np.array([0, 1, 1, 2])}[planes]


def ctx_mode(kind, prev):
    return CTX_MODE + kind * 4 + prev


def ctx_last(pc, mode, key):
    return CTX_LAST + (pc * 2 + (mode == MODE_INTRA)) * 2 + key


def ctx_mag(pc, band, key, nb):
    """nb: 0 = first (position last−1), 1..3 = 0..2 nonzeros among the two previous."""
    return CTX_MAG + ((pc * N_BANDS + band) * 2 + key) * 4 + nb


def ctx_esc(pc):
    return CTX_ESC + pc


def bucket_of(r: np.ndarray) -> np.ndarray:
    """Escape bucket k of remainders r >= 0: r + 1 in [2^k, 2^(k+1))."""
    return np.floor(np.log2(r.astype(np.float64) + 1)).astype(np.int64)


# -- encoder ---------------------------------------------------------------------------------
def block_symbols(modes: np.ndarray, levels: np.ndarray, kind: np.ndarray, key: np.ndarray, pcs: np.ndarray,
                  counts_only: bool = False):
    """The symbols and raw bits of S blocks.

    Args:
        modes: (S, nt) tb modes. levels: (S, nt, P, 64) signed levels in scan order (ignored
            where the tb's mode is skip). kind, key: (S,) view kind (0/1) and key flag (0/1).
        pcs: (P,) plane classes.

    Returns:
        (lane, ctx, sym) flat int32, int16, int16 arrays in decode order per lane (lanes
        ascending), and (rlane, bits) flat int32, uint8 arrays of raw bits (0/1) in order per
        lane; with ``counts_only``,
        their (N_CTX, ALPHABET) counts only (:func:`count_symbols`: no ordering, no raw bits).
    """
    if counts_only:
        return _block_counts(modes, levels, kind, key, pcs)
    S, nt, P, _ = levels.shape
    levels = np.where((modes != MODE_SKIP)[:, :, None, None], levels, 0)
    mag = np.abs(levels)
    nzmask = mag > 0
    last = np.where(nzmask.any(-1), 63 - np.argmax(nzmask[..., ::-1], axis=-1) + 1, 0)       # (S, nt, P)
    # Each lane's symbols in decode order: its tb modes, then the last positions of its coded
    # (tb, plane) pairs, then their magnitudes (pair by pair, j = 0..last-1), then the escapes'
    # buckets in the same order. Every part below is made lane by lane in that order already
    # (np.nonzero and the group expansion are row-major), so each symbol's place is its lane's
    # start plus its rank within its part: scattered there (no sort of the whole call).
    prev = np.concatenate([np.full((S, 1), 3), modes[:, :-1]], axis=1)
    coded = np.broadcast_to((modes != MODE_SKIP)[:, :, None], (S, nt, P))
    s_, t_, p_ = np.nonzero(coded)
    # magnitudes: group g = (s, t, p) with last > 0; j = 0..last-1 at scan position last-1-j
    gs, gt, gp = np.nonzero(last > 0)
    gl = last[gs, gt, gp]
    n = int(gl.sum())
    grp = np.repeat(np.arange(gs.size), gl)
    j = np.arange(n) - np.repeat(np.cumsum(gl) - gl, gl)
    pos = gl[grp] - 1 - j
    ms, mt, mp = gs[grp], gt[grp], gp[grp]
    m = mag[ms, mt, mp, pos]
    first = j == 0
    sym = np.minimum(np.where(first, m - 1, m), ESC)
    nz = m > 0
    prev1 = np.concatenate([[False], nz])[:n] & (j >= 1)
    prev2 = np.concatenate([[False, False], nz])[:n] & (j >= 2)
    nb = np.where(first, 0, 1 + prev1.astype(np.int64) + prev2)
    pc = pcs[mp]
    esc = sym == ESC
    r = m[esc] - ESC - np.where(first[esc], 1, 0)
    k = bucket_of(r)
    e_lane = ms[esc]
    n_last = np.bincount(s_, minlength=S)
    n_mag = np.bincount(ms, minlength=S)
    n_esc = np.bincount(e_lane, minlength=S)
    per = nt + n_last + n_mag + n_esc
    at = np.cumsum(per) - per                                    # each lane's first symbol

    def ranks(lanes, counts):                                    # rank within its lane (lanes ascending)
        return np.arange(lanes.size) - (np.cumsum(counts) - counts)[lanes]

    tot = int(per.sum())
    ctx = np.empty(tot, np.int16)
    syms = np.empty(tot, np.int16)
    i = (at[:, None] + np.arange(nt)).reshape(-1)
    ctx[i], syms[i] = ctx_mode(kind[:, None], prev).reshape(-1), modes.reshape(-1)
    i = at[s_] + nt + ranks(s_, n_last)
    ctx[i], syms[i] = ctx_last(pcs[p_], modes[s_, t_], key[s_]), last[s_, t_, p_]
    i = at[ms] + nt + n_last[ms] + ranks(ms, n_mag)
    ctx[i], syms[i] = ctx_mag(pc, BAND[pos], key[ms], nb), sym
    i = at[e_lane] + nt + n_last[e_lane] + n_mag[e_lane] + ranks(e_lane, n_esc)
    ctx[i], syms[i] = ctx_esc(pc[esc]), k
    # raw bits per lane: the signs in magnitude order, then each escape's suffix (k bits, LSB first)
    sign_lane = ms[nz]
    sign_bits = (levels[ms, mt, mp, pos] < 0)[nz]
    suffix = r - ((1 << k) - 1)
    el = np.repeat(e_lane, k)
    eb = np.arange(int(k.sum())) - np.repeat(np.cumsum(k) - k, k)
    ebits = (np.repeat(suffix, k) >> eb) & 1
    n_sign = np.bincount(sign_lane, minlength=S)
    n_ebit = np.bincount(el, minlength=S)
    rper = n_sign + n_ebit
    rat = np.cumsum(rper) - rper
    rbits = np.empty(int(rper.sum()), np.uint8)
    rbits[rat[sign_lane] + ranks(sign_lane, n_sign)] = sign_bits
    rbits[rat[el] + n_sign[el] + ranks(el, n_ebit)] = ebits
    # compact types (12 bytes a symbol, 5 a raw bit, not 24 and 16): the packer holds many
    # parts at once
    return (np.repeat(np.arange(S, dtype=np.int32), per), ctx, syms, np.repeat(np.arange(S, dtype=np.int32), rper),
            rbits)


def _block_counts(modes: np.ndarray, levels: np.ndarray, kind: np.ndarray, key: np.ndarray,
                  pcs: np.ndarray) -> np.ndarray:
    """:func:`block_symbols`' (N_CTX, ALPHABET) counts, without the order, lanes or raw bits it
    builds for packing: each symbol's context and value go straight into one flat code per
    symbol, the magnitudes read by flat index (the rate search measures an entropy model from
    every pass: 0.4-0.5x the time of counting the packer's symbols)."""
    S, nt, P, _ = levels.shape
    coded = modes != MODE_SKIP                                          # (S, nt)
    nzmask = levels != 0
    any_nz = nzmask.any(-1)
    last = np.where(any_nz & coded[:, :, None], 64 - np.argmax(nzmask[..., ::-1], axis=-1), 0)   # (S, nt, P)
    prev = np.concatenate([np.full((S, 1), 3), modes[:, :-1]], axis=1)
    codes = [ctx_mode(kind[:, None], prev).reshape(-1) * ALPHABET + modes.reshape(-1)]
    s_, t_, p_ = np.nonzero(np.broadcast_to(coded[:, :, None], (S, nt, P)))
    codes.append(ctx_last(pcs[p_], modes[s_, t_], key[s_]) * ALPHABET + last[s_, t_, p_])
    # magnitudes: group g = (s, t, p) with last > 0; its symbol j = 0..last-1 is at scan position
    # last-1-j; symbols flat, group after group (st: each group's first)
    g = np.flatnonzero(last.reshape(-1) > 0)                            # flat (s, t, p) of each group
    gl = last.reshape(-1)[g]
    n = int(gl.sum())
    st = np.cumsum(gl) - gl
    at = np.repeat((g << 6) + gl - 1 + st, gl)
    at -= np.arange(n)                                                  # flat index into levels
    m = np.abs(levels.reshape(-1).take(at))
    nz = m > 0
    m[st] -= 1                                                          # (the first is never 0)
    esc = np.flatnonzero(m >= ESC)                                      # escapes: ESC + bucket + suffix
    if esc.size:
        codes.append(ctx_esc(pcs[(at[esc] >> 6) % P]) * ALPHABET + bucket_of(m[esc] - ESC))
    sym = np.minimum(m, ESC, out=m)
    one = np.ones(n, bool)                                              # j >= 1
    one[st] = False
    two = one.copy()                                                    # j >= 2
    two[st[gl >= 2] + 1] = False
    nb = one.astype(np.int8)                                            # first 0, else 1 + nonzeros
    nb[1:] += nz[:-1] & one[1:]                                         # among the two previous
    nb[2:] += nz[:-2] & two[2:]
    code = np.repeat(ctx_mag(pcs[g % P], 0, key[g // (nt * P)], 0) * ALPHABET, gl)   # plane class, key
    code += _BAND8_65[at & 63]
    code += nb * np.int64(ALPHABET)
    code += sym
    codes.append(code)
    flat = np.concatenate(codes)
    return np.bincount(flat, minlength=N_CTX * ALPHABET).astype(np.int64).reshape(N_CTX, ALPHABET)


PACK_CELLS = 1 << 22          # lanes × longest lane coded at once (two int32 matrices of this size)


def pack_streams(S: int, lane, ctx, sym, rlane, rbits, tables: Tables) -> list[bytes]:
    """rANS-encode the symbols of S lanes and append each lane's raw bits. Lanes are coded
    in consecutive groups whose lanes × longest lane stays within PACK_CELLS (each lane's bytes
    depend on its own symbols only, so the grouping changes no byte; one long key-view row
    beside thousands of short blocks would otherwise make an S × K matrix of gigabytes)."""
    counts = np.bincount(lane, minlength=S)
    K = int(counts.max(initial=0))
    if S > 1 and S * K > PACK_CELLS and not (np.diff(lane) < 0).any() and not (np.diff(rlane) < 0).any():
        # greedy consecutive groups: extend while (lanes in group) × (longest so far) fits
        out: list = []
        a = 0
        lo = np.searchsorted(lane, np.arange(S + 1))              # lane is sorted (lanes ascending)
        rlo = np.searchsorted(rlane, np.arange(S + 1))
        while a < S:
            b, kmax = a, 0
            while b < S:
                k2 = max(kmax, int(counts[b]))
                if b > a and (b - a + 1) * k2 > PACK_CELLS:
                    break
                kmax, b = k2, b + 1
            sl, rs_ = slice(lo[a], lo[b]), slice(rlo[a], rlo[b])
            out += _pack_group(b - a, lane[sl] - a, ctx[sl], sym[sl], rlane[rs_] - a, rbits[rs_], tables)
            a = b
        return out
    return _pack_group(S, lane, ctx, sym, rlane, rbits, tables)


def _pack_group(S: int, lane, ctx, sym, rlane, rbits, tables: Tables) -> list[bytes]:
    counts = np.bincount(lane, minlength=S)
    K = int(counts.max(initial=0))
    starts = np.cumsum(counts) - counts
    col = np.arange(lane.size) - starts[lane]
    C = np.zeros((S, max(K, 1)), np.int32)           # (contexts and symbols are small: 4 bytes a cell)
    Y = np.zeros((S, max(K, 1)), np.int32)
    C[lane, col], Y[lane, col] = ctx, sym
    rc = np.bincount(rlane, minlength=S)
    rs = np.cumsum(rc) - rc
    k = np.minimum(rc, BACK_BITS)                         # raw bits carried by the start state
    col = np.arange(rlane.size) - rs[rlane]
    inback = col < k[rlane]
    back = np.zeros(S, np.int64)
    np.add.at(back, rlane[inback], rbits[inback].astype(np.int64) << col[inback])
    rans = encode_lanes(C, Y, counts, tables, back=back)
    out = []
    for i in range(S):
        bits = rbits[rs[i] + k[i]:rs[i] + rc[i]].astype(np.uint8)
        out.append(rans[i] + np.packbits(bits, bitorder="little").tobytes())
    return out


def count_symbols(ctx, sym) -> np.ndarray:
    """(N_CTX, ALPHABET) counts of (context, symbol) pairs."""
    flat = np.asarray(ctx, np.int64) * ALPHABET + np.asarray(sym, np.int64)
    return np.bincount(flat, minlength=N_CTX * ALPHABET).astype(np.int64).reshape(N_CTX, ALPHABET)


# -- tables on the wire ----------------------------------------------------------------------
def quantize_counts(counts: np.ndarray) -> np.ndarray:
    """(N_CTX, A) counts → one byte per count: 0 = unused, else 1 + round(8·log2(count)) capped
    at 255 (the table both sides build from :func:`dequantize_counts`)."""
    c = np.asarray(counts, np.float64)
    q = np.where(c > 0, 1 + np.rint(8 * np.log2(np.maximum(c, 1))), 0)
    return np.minimum(q, 255).astype(np.uint8)


def dequantize_counts(q: np.ndarray) -> np.ndarray:
    return np.where(q > 0, np.exp2((q.astype(np.float64) - 1) / 8), 0.0)


#: integer weight of each quantized count (format version ≥ 2): 0 for 0, else round(2^((q−1)/8))
#: (never a tie: 2^(k/8) is an integer or irrational).
COUNT_WEIGHT = np.array([0] + [int(round(2.0 ** ((q - 1) / 8))) for q in range(1, 256)], dtype=np.int64)


def tables_from_quantized(q: np.ndarray, version: int = 2) -> Tables:
    """rANS tables from quantized counts; unused contexts get a flat table over the whole
    alphabet (never used by a valid stream). Version 2: integer weights
    (:data:`COUNT_WEIGHT`, :func:`rlfc.rans.normalize_int`); version 1 (first tx files):
    float weights and :func:`rlfc.rans.normalize`."""
    if version >= 2:
        return Tables.from_weights(COUNT_WEIGHT[np.asarray(q, np.int64)])
    return Tables.from_counts(dequantize_counts(q))


def tables_to_bytes(q: np.ndarray) -> bytes:
    """Used contexts only: a context bitmap, then per used context a symbol bitmap and one
    byte per used symbol; zlib-compressed."""
    import zlib

    used_ctx = (q > 0).any(axis=1)
    parts = [np.packbits(used_ctx, bitorder="little").tobytes()]
    for c in np.flatnonzero(used_ctx):
        row = q[c]
        parts.append(np.packbits(row > 0, bitorder="little").tobytes())
        parts.append(row[row > 0].tobytes())
    return zlib.compress(b"".join(parts), 9)


def tables_from_bytes(data: bytes, name: str) -> np.ndarray:
    """Inverse of :func:`tables_to_bytes` → (N_CTX, ALPHABET) quantized counts."""
    return tables_from_bytes_n(data, N_CTX, ALPHABET, name)


def tables_from_bytes_n(data: bytes, n_ctx: int, alphabet: int, name: str) -> np.ndarray:
    """Inverse of :func:`tables_to_bytes` for (n_ctx, alphabet) tables."""
    import zlib

    limit = (n_ctx + 7) // 8 + n_ctx * ((alphabet + 7) // 8 + alphabet)
    try:
        d = zlib.decompressobj()
        raw = d.decompress(bytes(data), limit + 1)
    except zlib.error as e:
        raise FormatError(f"{name}: rANS tables are not a valid stream ({e})") from None
    if not d.eof or d.unused_data or len(raw) > limit:
        raise FormatError(f"{name}: rANS tables stream is malformed")
    b = np.frombuffer(raw, np.uint8)
    q = np.zeros((n_ctx, alphabet), np.uint8)
    nb = (n_ctx + 7) // 8
    if b.size < nb:
        raise FormatError(f"{name}: rANS tables are truncated")
    used = np.unpackbits(b[:nb], bitorder="little")[:n_ctx].astype(bool)
    pos, ab = nb, (alphabet + 7) // 8
    for c in np.flatnonzero(used):
        if pos + ab > b.size:
            raise FormatError(f"{name}: rANS tables are truncated")
        sm = np.unpackbits(b[pos:pos + ab], bitorder="little")[:alphabet].astype(bool)
        pos += ab
        k = int(sm.sum())
        if k == 0 or pos + k > b.size:
            raise FormatError(f"{name}: rANS tables are truncated or empty")
        vals = b[pos:pos + k]
        if (vals == 0).any():
            raise FormatError(f"{name}: rANS tables hold a zero count")
        q[c, sm] = vals
        pos += k
    if pos != b.size:
        raise FormatError(f"{name}: rANS tables have {b.size - pos} trailing bytes")
    return q
