"""The ``tx.maps`` section: the shared disparity map, per-map corrections and prediction modes,
entropy-coded with rANS (:mod:`rlfc.rans`): the shared map when a file is opened, each other
map when a request first needs it (:class:`LazyMaps`).

Layout: u8 version (3; 2 = the escape digits of one shared context; 1 = the first files,
whose tables were built in float arithmetic); varint byte lengths of the tables and of each
stream; the tables
(:func:`rlfc.txsyntax.tables_to_bytes` layout over this module's contexts); the shared map's
stream; one stream per map.

Shared map (nby8 × nbx8 raster, 1/16 px per view step): each value v is coded as
e = v − MED(a, b, c) (a left, b above, c above-left; missing neighbours repeat the nearest
present one, the first value is predicted by 0; MED = median(a, b, a + b − c)), symbol
clamp(e, −31, 31) + 31, context by the activity |a − c| + |b − c| (0, 1..16, > 16).
Per map, one stream: for each block in raster order the correction (disparity − shared),
symbol clamp(c, −31, 31) + 31, context (left ≠ 0) + 2·(above ≠ 0); then for each block the
mode (0 blend, 1 + j reference j), context 5·left + above (missing: 0).
An escape (symbol 0 for e or c <= −31, 62 for >= 31) is followed by three 6-bit digits of the
excess |e| − 31, most significant first, each digit position in its own context
(CTX_DIGIT + position; versions 1-2: all three in CTX_DIGIT, where the high digits, nearly
always 0, and the low one, nearly uniform, shared one table: 21% of stanford_chess's maps).
"""
from __future__ import annotations

import numpy as np

from formats.errors import FormatError

from .rans import L as RANS_L, PROB_BITS, STATE_BYTES, encode_lanes, scalar_step, scalar_tables
from .txsections import MAX_VARINT_BYTES, unvarints, varints
from .txsyntax import quantize_counts, tables_from_bytes_n, tables_from_quantized, tables_to_bytes

VERSION = 3
R = 31
CTX_BASE = 0                 # 3 activity classes
CTX_CORR = 3                 # 4: left nonzero + 2 · above nonzero
CTX_MODE = 7                 # 25: 5·left + above
CTX_DIGIT = 32               # escape digits: one context per digit position (versions 1-2: one for all)
N_CTX = 35
ALPHABET = 64


def _n_ctx(version: int) -> int:
    return N_CTX if version >= 3 else CTX_DIGIT + 1


def _digit_ctx(version: int, k: int) -> int:
    """Context of escape digit k (0 = most significant)."""
    return CTX_DIGIT + k if version >= 3 else CTX_DIGIT


def _med(a, b, c):
    """MED(a, b, c) = median(a, b, a + b − c) of arrays (the decoder's scalar form: :func:`_shared_map`)."""
    return np.median(np.stack([a, b, a + b - c]), axis=0).astype(np.int64)


def _escape(e):
    """Symbol and escape digits of values e (arrays): digits of |e| − R in 3×6 bits, most
    significant first (the sign is the symbol's)."""
    sym = np.clip(e, -R, R) + R
    esc = np.abs(e) >= R
    x = np.abs(e) - R
    return sym, esc, np.stack([(x >> 12) & 63, (x >> 6) & 63, x & 63], -1)


def _activity(a, b, c):
    act = np.abs(a - c) + np.abs(b - c)
    return np.where(act == 0, 0, np.where(act <= 16, 1, 2))


def _neighbours(v: np.ndarray):
    """(a, b, c) left, above, above-left of a (ny, nx) grid, repeating the nearest present one."""
    ny, nx = v.shape
    a = np.empty_like(v)
    a[:, 1:] = v[:, :-1]
    a[:, 0] = np.concatenate([[0], v[:-1, 0]])
    b = np.empty_like(v)
    b[1:] = v[:-1]
    b[0] = a[0]
    c = np.empty_like(v)
    c[1:, 1:] = v[:-1, :-1]
    c[1:, 0] = b[1:, 0]
    c[0] = a[0]
    return a, b, c


def pack_maps(base: np.ndarray, disp: np.ndarray, modes: np.ndarray, shape: tuple[int, int],
              version: int = VERSION) -> bytes:
    """Section bytes of the shared map (nloc,), per-map disparities and modes (n_maps, nloc).
    ``version``: 3 (what the encoder writes) or 2 (the previous layout; tests of old files)."""
    lanes, q = _map_lanes(base, disp, modes, shape, version)
    streams = encode_lanes(*_lane_arrays(lanes), tables_from_quantized(q))
    tb = tables_to_bytes(q)
    return bytes([version]) + varints(np.array([len(tb)] + [len(x) for x in streams])) + tb + b"".join(streams)


def maps_bytes(base: np.ndarray, variants: list, shape: tuple[int, int]) -> list[float]:
    """Estimated ``len(pack_maps(base, disp, modes, shape))`` of each (disp, modes) in
    ``variants``, without coding them: each stream's information content under the tables its
    variant would be coded with (Σ over its symbols of PROB_BITS − log2 of the symbol's
    quantized frequency, in bytes), plus its rANS state; the tables and the lengths' varints
    exactly. An rANS stream is that content to within a few bytes, so the difference between
    two variants (what the encoder asks: the bytes one map costs) is off by a few bytes in a
    few hundred: on the 40 dB files of four dense grids, 0–5 bytes per map against the coded
    sizes (tests bound it), at a fifth of the time of coding every variant."""
    out = []
    for d, m in variants:
        lanes, q = _map_lanes(base, d, m, shape, VERSION)
        bits = PROB_BITS - np.log2(np.maximum(tables_from_quantized(q).freq, 1))      # (contexts, symbols)
        lens = [STATE_BYTES + float(bits[c, sym].sum()) / 8 for c, sym in lanes]
        tb = len(tables_to_bytes(q))
        out.append(1 + len(varints(np.array([tb] + [round(x) for x in lens]))) + tb + sum(lens))
    return out


def _map_lanes(base, disp, modes, shape, version) -> tuple[list, np.ndarray]:
    """The maps section's streams as (ctx, sym) lanes (the shared map, then one per map) and
    their quantized counts."""
    if version not in (2, VERSION):
        raise ValueError(f"maps version must be 2 or {VERSION}, got {version}")
    ny, nx = shape
    lanes = []                                           # per stream: list of (ctx, sym)
    b = base.reshape(ny, nx).astype(np.int64)
    a_, b_, c_ = _neighbours(b)
    pred = _med(a_, b_, c_)
    pred[0, 0] = 0
    e = (b - pred).reshape(-1)
    ctx0 = _activity(a_, b_, c_).reshape(-1) + CTX_BASE
    lanes.append(_with_escapes(ctx0, e, version))
    corr = (disp - base[None, :]).astype(np.int64)
    for m in range(disp.shape[0]):
        cm = corr[m].reshape(ny, nx)
        left = np.concatenate([np.zeros((ny, 1), np.int64), cm[:, :-1]], 1) != 0
        up = np.concatenate([np.zeros((1, nx), np.int64), cm[:-1]], 0) != 0
        cc, cs = _with_escapes((CTX_CORR + left + 2 * up).reshape(-1), cm.reshape(-1), version)
        mo = modes[m].reshape(ny, nx).astype(np.int64)
        ml = np.concatenate([np.zeros((ny, 1), np.int64), mo[:, :-1]], 1)
        mu = np.concatenate([np.zeros((1, nx), np.int64), mo[:-1]], 0)
        lanes.append((np.concatenate([cc, (CTX_MODE + 5 * ml + mu).reshape(-1)]), np.concatenate([cs, mo.reshape(-1)])))
    counts = np.zeros((_n_ctx(version), ALPHABET), np.int64)
    for c, s in lanes:
        np.add.at(counts, (c, s), 1)
    return lanes, quantize_counts(counts)


def _lane_arrays(lanes: list):
    """(ctx, sym, lengths) arrays of :func:`rlfc.rans.encode_lanes` from (ctx, sym) lanes."""
    K = max(len(c) for c, _ in lanes)
    C = np.zeros((len(lanes), K), np.int64)
    S = np.zeros((len(lanes), K), np.int64)
    for i, (c, s) in enumerate(lanes):
        C[i, :len(c)], S[i, :len(s)] = c, s
    return C, S, np.array([len(c) for c, _ in lanes])


def _with_escapes(ctx: np.ndarray, v: np.ndarray, version: int):
    """(ctx, sym) in order, each escape followed by its three digits."""
    sym, esc, dig = _escape(v)
    n = 1 + 3 * esc
    pos = np.cumsum(n) - n
    out_c = np.zeros(int(n.sum()), np.int64)
    out_s = np.zeros(int(n.sum()), np.int64)
    out_c[pos], out_s[pos] = ctx, sym
    ei = pos[esc]
    for k in range(3):
        out_c[ei + 1 + k] = _digit_ctx(version, k)
        out_s[ei + 1 + k] = dig[esc, k]
    return out_c, out_s


def unpack_maps(data, n_maps: int, shape: tuple[int, int], n_modes: int, what: str):
    """→ (per-map disparities (n_maps, nloc), modes (n_maps, nloc)), int64: every map decoded
    (:class:`LazyMaps` decodes them one by one, as they are asked for)."""
    return LazyMaps(data, n_maps, shape, n_modes, what).all()


class LazyMaps:
    """The maps of a ``tx.maps`` section, each decoded when first asked for.

    Opening reads the section's lengths and tables; :meth:`need` decodes the shared map (one
    stream) with the first map asked for, and the per-map streams asked for (a request touches
    the maps of its views only: a first frame one to five of a grid's dozens; a posed capture's
    views have none). ``disp`` and ``modes`` (n_maps, nloc) int64 hold the decoded maps' rows
    (zeros elsewhere); ``done`` (n_maps,) bool says which.
    A map's stream is checked when it is decoded (its symbols, its end, its disparities within
    ±2^20 and its modes at most ``max_mode[m]``): a damaged map raises
    :class:`formats.errors.FormatError` at its first use, not at open. Not thread-safe: callers
    that share one across threads call :meth:`need` under a lock."""

    def __init__(self, data, n_maps: int, shape: tuple[int, int], n_modes: int, what: str, max_mode=None):
        if not 1 <= n_modes <= 5:
            raise ValueError("a map's modes are 0..4 (contexts 5·left + above)")
        ny, nx = shape
        nloc = ny * nx
        raw = self.raw = bytes(data)
        if not raw or raw[0] not in (1, 2, VERSION):
            raise FormatError(f"{what}: unknown maps version")
        ver = self.version = raw[0]
        b = np.frombuffer(raw, np.uint8)
        ends = np.flatnonzero(b[1:] < 128)
        if ends.size < n_maps + 2:
            raise FormatError(f"{what}: truncated stream lengths")
        head = 1 + int(ends[n_maps + 1]) + 1
        lens = unvarints(raw[1:head], n_maps + 2, what)
        if (lens < 0).any() or head + int(lens.sum()) != len(raw):
            raise FormatError(f"{what}: stream lengths do not add up to the section")
        pos = head + int(lens[0])
        tables = tables_from_quantized(tables_from_bytes_n(raw[head:pos], _n_ctx(ver), ALPHABET, what), ver)
        self.tabs = scalar_tables(tables)
        # the shared map: one stream, sequential (MED needs the decoded neighbours), decoded with
        # the first map asked for (a file whose views are all intra asks for none)
        self._base_span, self._base = (pos, pos + int(lens[1])), None
        pos += int(lens[1])
        self.starts = pos + np.concatenate([[0], np.cumsum(lens[2:])]).astype(np.int64)    # (n_maps + 1,)
        self.shape, self.n_modes, self.what = (ny, nx), n_modes, what
        self.max_mode = np.full(n_maps, n_modes - 1, np.int64) if max_mode is None else np.asarray(max_mode)
        self.disp = np.zeros((n_maps, nloc), np.int64)
        self.modes = np.zeros((n_maps, nloc), np.int64)
        self.done = np.zeros(n_maps, bool)

    @property
    def base(self) -> np.ndarray:
        """(nloc,) int64 the shared map (every map's disparities are corrections to it), decoded on
        first use (:class:`formats.errors.FormatError` where its stream is damaged)."""
        if self._base is None:
            a, b = self._base_span
            self._base = np.asarray(_shared_map(self.raw[a:b], self.tabs, *self.shape, self.version, self.what),
                                    np.int64)
        return self._base

    def need(self, maps) -> list[int]:
        """Decode maps ``maps`` (ints) not decoded yet; → those decoded now (ascending)."""
        new = sorted({int(m) for m in np.asarray(maps).reshape(-1).tolist()} - set(np.flatnonzero(self.done).tolist()))
        ny, nx = self.shape
        for m in new:
            # one stream per map (contexts from the same map's left and above values), plain
            # Python: a map's symbols depend on each other, and a few dozen maps make poor numpy lanes
            corr, mo = _map_stream(self.raw, int(self.starts[m]), int(self.starts[m + 1]), self.tabs, ny, nx,
                                   self.n_modes, self.version, self.what)
            dm = np.asarray(corr, np.int64) + self.base
            mo = np.asarray(mo, np.int64)
            if dm.size and np.abs(dm).max() > (1 << 20):
                raise FormatError(f"{self.what}: a disparity is out of range")
            if mo.size and mo.max() > self.max_mode[m]:
                raise FormatError(f"{self.what} selects a reference a view does not have")
            self.disp[m], self.modes[m] = dm, mo
            self.done[m] = True
        return new

    def all(self):
        """(disp, modes) with every map decoded."""
        self.need(np.arange(self.done.size))
        return self.disp, self.modes


def _escape_digits(tabs, digits: list, x: int, p: int, data) -> tuple[int, int, int]:
    """An escape's excess |e| − R from its three 6-bit digits (contexts ``digits``, most
    significant first; ``tabs``: :func:`rlfc.rans.scalar_tables`), the rANS state x at byte p of
    ``data``: (excess, x, p) after them. (Reads past ``data`` raise IndexError: the callers
    make it a FormatError.)"""
    e = 0
    for dc in digits:
        g, x, p = scalar_step(*tabs, dc, x, p, data)
        e = (e << 6) | g
    return e, x, p


def _shared_map(data: bytes, tabs, ny: int, nx: int, ver: int, what: str) -> list:
    """The shared map's ny·nx values (a list of ints, raster order) from its stream ``data``:
    each value MED(a, b, c) + e, e's symbol in the context of the activity at that block (the
    module's docstring); the rANS steps of :class:`rlfc.rans.ScalarDecoder` inlined on ``tabs``
    (:func:`rlfc.rans.scalar_tables`), on Python ints (numpy scalars made this 4x slower: it is
    paid by every open)."""
    if len(data) < STATE_BYTES:
        raise FormatError(f"{what}: the shared map's stream is shorter than its state")
    slot_t, freq_t, cum_t = tabs
    x = int.from_bytes(data[:STATE_BYTES], "little")
    p = STATE_BYTES
    vals = [0] * (ny * nx)
    digits = [_digit_ctx(ver, k) for k in range(3)]
    mask = (1 << PROB_BITS) - 1
    # the common symbol, e = 0 where the three neighbours are equal (the prediction is then
    # their value): decoded from locals, without the tables or the median
    lo0 = cum_t[CTX_BASE][R]
    f0 = freq_t[CTX_BASE][R]
    hi0 = lo0 + f0
    i = 0
    try:
        for y in range(ny):
            for xx in range(nx):
                if xx:
                    a = vals[i - 1]
                    b = vals[i - nx] if y else a
                    c = vals[i - nx - 1] if y else a
                else:
                    a = vals[i - nx] if y else 0
                    b = c = a
                sl = x & mask
                if a == b == c and lo0 <= sl < hi0:
                    x = f0 * (x >> PROB_BITS) + sl - lo0
                    while x < RANS_L:
                        x = (x << 8) | data[p]
                        p += 1
                    vals[i] = a
                    i += 1
                    continue
                act = abs(a - c) + abs(b - c)
                ctx = CTX_BASE + (0 if act == 0 else 1 if act <= 16 else 2)
                s = slot_t[ctx][sl]
                x = freq_t[ctx][s] * (x >> PROB_BITS) + sl - cum_t[ctx][s]
                while x < RANS_L:
                    x = (x << 8) | data[p]
                    p += 1
                if s == 0 or s == 2 * R:                  # an escape: three 6-bit digits of |e| − R
                    e, x, p = _escape_digits(tabs, digits, x, p, data)
                    e = R + e if s else -(R + e)
                elif s > 2 * R:
                    raise FormatError(f"{what}: undefined map symbol {s}")
                else:
                    e = s - R
                if i == 0:
                    vals[0] = e
                else:                                     # MED = median(a, b, a + b − c)
                    lo, hi = (a, b) if a <= b else (b, a)
                    vals[i] = e + (lo if c >= hi else hi if c <= lo else a + b - c)
                i += 1
    except IndexError:
        raise FormatError(f"{what}: the shared map's stream reads past its end") from None
    if p != len(data) or x != RANS_L:
        raise FormatError(f"{what}: the shared map's stream is malformed")
    return vals


def _map_stream(data: bytes, start: int, end: int, tabs, ny: int, nx: int, n_modes: int, ver: int,
                what: str) -> tuple[list, list]:
    """(corrections, modes), lists of ny·nx ints, of one map's stream ``data[start:end]``: the
    rANS steps of :class:`rlfc.rans.ScalarDecoder` inlined on ``tabs``
    (:func:`rlfc.rans.scalar_tables`: per context the slot → symbol bytes, the frequencies and
    the cums; Python ints below 2^30, CPython's one-digit ints, where one 32-bit word per slot
    took two-digit ones)."""
    if not 1 <= n_modes <= 5:
        raise ValueError("a map's modes are 0..4 (contexts 5·left + above)")
    slot_t, freq_t, cum_t = tabs
    nloc = ny * nx
    if end - start < STATE_BYTES:
        raise FormatError(f"{what}: a map stream is shorter than its state")
    x = int.from_bytes(data[start:start + STATE_BYTES], "little")
    p = start + STATE_BYTES
    corr = [0] * nloc
    nz = [0] * (nloc + nx)                    # 2·(correction != 0), after a zero row
    digits = [_digit_ctx(ver, k) for k in range(3)]
    mask = (1 << PROB_BITS) - 1
    # the common symbols (a zero correction, mode 0, where the left and above ones are zero too)
    # decoded from locals, without the tables
    lo0, f0 = cum_t[CTX_CORR][R], freq_t[CTX_CORR][R]
    hi0 = lo0 + f0
    mlo0, mf0 = cum_t[CTX_MODE][0], freq_t[CTX_MODE][0]
    mhi0 = mlo0 + mf0
    i = 0
    try:
        for _ in range(ny):
            left = 0
            for _ in range(nx):
                sl = x & mask
                if not (left or nz[i]) and lo0 <= sl < hi0:
                    x = f0 * (x >> PROB_BITS) + sl - lo0
                    while x < RANS_L:
                        x = (x << 8) | data[p]
                        p += 1
                    i += 1                            # (its nz stays 0)
                    continue
                ctx = CTX_CORR + left + nz[i]
                s = slot_t[ctx][sl]
                x = freq_t[ctx][s] * (x >> PROB_BITS) + sl - cum_t[ctx][s]
                while x < RANS_L:
                    x = (x << 8) | data[p]
                    p += 1
                if s == R:
                    left = 0
                else:
                    if s == 0 or s == 2 * R:          # an escape: three 6-bit digits of |c| − R
                        e, x, p = _escape_digits(tabs, digits, x, p, data)
                        corr[i] = R + e if s else -(R + e)
                    elif s > 2 * R:
                        raise FormatError(f"{what}: undefined map symbol {s}")
                    else:
                        corr[i] = s - R
                    left = 1
                nz[i + nx] = left + left
                i += 1
        modes = [0] * (nloc + nx)              # after a zero row
        i = 0
        for _ in range(ny):
            ml = 0
            for _ in range(nx):
                sl = x & mask
                if not (ml or modes[i]) and mlo0 <= sl < mhi0:
                    x = mf0 * (x >> PROB_BITS) + sl - mlo0
                    while x < RANS_L:
                        x = (x << 8) | data[p]
                        p += 1
                    i += 1                            # (its mode stays 0)
                    continue
                ctx = CTX_MODE + 5 * ml + modes[i]
                ml = slot_t[ctx][sl]
                x = freq_t[ctx][ml] * (x >> PROB_BITS) + sl - cum_t[ctx][ml]
                while x < RANS_L:
                    x = (x << 8) | data[p]
                    p += 1
                if ml >= n_modes:
                    raise FormatError(f"{what}: a prediction mode is out of range")
                modes[i + nx] = ml
                i += 1
    except IndexError:
        raise FormatError(f"{what}: a map stream reads past the section") from None
    if p != end or x != RANS_L:
        raise FormatError(f"{what}: a map stream is malformed")
    return corr, modes[nx:]


__all__ = ["pack_maps", "maps_bytes", "unpack_maps", "LazyMaps", "MAX_VARINT_BYTES"]
