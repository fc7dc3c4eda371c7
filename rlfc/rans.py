"""Static-table rANS (range asymmetric numeral systems), byte-wise, after F. Giesen's ryg_rans.

One stream per random-access unit: each decodes on its own. Frequency tables are stored once
per file (:class:`Tables`); a symbol is coded with the table of its context.

Coder (all integers exact; on-wire constants, do not change):
    PROB_BITS n = 12 (frequencies of a table sum to M = 4096); state x in [L, 256·L), L = 2^15.
    Encode s (freq f, cumulative c), symbols in reverse order: while x >= ((L >> n) << 8)·f:
    emit the byte x & 255, x >>= 8; then x = ((x // f) << n) + (x % f) + c. Start: x = L + R,
    R < L (R carries up to 15 bits of the caller's raw data for free: "bits back").
    Stream bytes, first to last: the final state (3 bytes, little-endian), then the emitted
    bytes in the reverse of their emission order.
    Decode: x = the first 3 bytes (LE); per symbol: slot = x & (M−1); s = the symbol whose
    [c, c + f) holds slot; x = f·(x >> n) + slot − c; while x < L: x = (x << 8) | next byte.
    A valid stream ends with x = L + R, having read exactly its own bytes.

Decoders: :class:`LaneDecoder` steps many streams at once (numpy or torch via :mod:`rlfc.xp`);
:class:`ScalarDecoder` is plain Python ints (one stream; also the slow reference the lanes are
tested against). :func:`encode_lanes` encodes many streams at once (numpy).
"""
from __future__ import annotations

import zlib

import numpy as np

from formats.errors import FormatError

PROB_BITS = 12
M = 1 << PROB_BITS
L = 1 << 15
STATE_BYTES = 3                              # the state is < 256·L = 2^23
BACK_BITS = 15                               # raw bits the start state can carry (R < L)
_XMAX_SCALE = (L >> PROB_BITS) << 8          # x_max(f) = _XMAX_SCALE · f


def normalize(counts: np.ndarray) -> np.ndarray:
    """(A,) symbol counts → (A,) frequencies summing to M; every counted symbol gets >= 1.

    Symbols never counted get 0 (they cannot be coded). Deterministic: largest remainders,
    ties to the lower symbol. An all-zero count gets a flat table.
    """
    c = np.asarray(counts, dtype=np.float64)
    A = c.size
    if c.sum() <= 0:
        c = np.ones(A)
    used = c > 0
    if used.sum() > M:
        raise ValueError(f"{used.sum()} symbols do not fit a table of {M}")
    f = np.where(used, np.maximum(1, np.floor(c / c.sum() * M)), 0).astype(np.int64)
    diff = M - int(f.sum())
    if diff > 0:                              # hand out the rest by largest remainder
        rem = np.where(used, c / c.sum() * M - np.floor(c / c.sum() * M), -1.0)
        order = np.lexsort((np.arange(A), -rem))
        for i in range(diff):
            f[order[i % used.sum()]] += 1
    while diff < 0:                           # the floor at 1 overshot: take from the largest
        j = int(np.argmax(f))
        take = min(-diff, int(f[j]) - 1)
        f[j] -= take
        diff += take
    return f


def normalize_int(weights: np.ndarray) -> np.ndarray:
    """(A,) non-negative integer weights → (A,) frequencies summing to M, in integers only
    (the rule of format versions ≥ 2; a decoder in any language gets the same table).

    With T = Σw: f = max(1, ⌊w·M/T⌋) for w > 0, else 0. If Σf < M, the M − Σf extra units go
    one each to the used symbols in order of decreasing remainder (w·M mod T), ties to the
    lower symbol, cycling if needed. If Σf > M, the first largest f gives back units (never
    below 1) until Σf = M. All-zero weights count as all ones.
    """
    w = np.asarray(weights, dtype=np.int64)
    if (w < 0).any() or (w > 1 << 40).any():
        raise ValueError("weights must be within [0, 2^40]")
    A = w.size
    if w.sum() <= 0:
        w = np.ones(A, np.int64)
    used = w > 0
    n_used = int(used.sum())
    if n_used > M:
        raise ValueError(f"{n_used} symbols do not fit a table of {M}")
    T = int(w.sum())
    num = w * M
    f = np.where(used, np.maximum(1, num // T), 0).astype(np.int64)
    diff = M - int(f.sum())
    if diff > 0:
        rem = np.where(used, num % T, -1)
        order = np.lexsort((np.arange(A), -rem))
        for i in range(diff):
            f[order[i % n_used]] += 1
    while diff < 0:
        j = int(np.argmax(f))
        take = min(-diff, int(f[j]) - 1)
        f[j] -= take
        diff += take
    return f


def normalize_int_rows(weights: np.ndarray) -> np.ndarray:
    """(C, A) non-negative integer weights → (C, A) frequencies: :func:`normalize_int` of each
    row, the rows in bulk (a file's ~200 tables cost 5 ms one by one, paid by every open).

    Rows whose floors overshoot M (the floor at 1 of many rare symbols), the rare case, go
    through :func:`normalize_int` itself."""
    w = np.asarray(weights, dtype=np.int64)
    if w.ndim != 2:
        raise ValueError("weights must be (contexts, symbols)")
    if (w < 0).any() or (w > 1 << 40).any():
        raise ValueError("weights must be within [0, 2^40]")
    C, A = w.shape
    w = np.where((w.sum(axis=1) <= 0)[:, None], 1, w)            # all-zero rows count as all ones
    used = w > 0
    n_used = used.sum(axis=1)
    if (n_used > M).any():
        raise ValueError(f"{int(n_used.max())} symbols do not fit a table of {M}")
    T = w.sum(axis=1, keepdims=True)
    num = w * M
    f = np.where(used, np.maximum(1, num // T), 0)
    diff = M - f.sum(axis=1)
    # Σ⌊w·M/T⌋ > M − n_used, so a row short of M is short by fewer units than it has symbols:
    # its first `diff` symbols by decreasing remainder (ties: lower symbol) get one unit each
    up = np.flatnonzero(diff > 0)
    if up.size:
        rem = np.where(used[up], num[up] % T[up], -1)
        order = np.lexsort((np.broadcast_to(np.arange(A), rem.shape), -rem), axis=-1)
        take = np.arange(A)[None, :] < diff[up, None]
        f[np.repeat(up, take.sum(axis=1)), order[take]] += 1
    for r in np.flatnonzero(diff < 0).tolist():
        f[r] = normalize_int(w[r])
    return f


class Tables:
    """Frequency tables of C contexts over an alphabet of A symbols.

    Attributes:
        freq: (C, A) int64 frequencies (each row sums to M). cum: (C, A + 1) cumulative.
        slot: (C, M) int64: the symbol of each slot (the decoder's look-up).
    """

    def __init__(self, freq: np.ndarray):
        freq = np.asarray(freq, dtype=np.int64)
        if freq.ndim != 2 or (freq < 0).any() or (freq.sum(axis=1) != M).any():
            raise FormatError(f"rANS tables must be rows of non-negative frequencies summing to {M}")
        self.freq = freq
        C, A = freq.shape
        self.cum = np.zeros((C, A + 1), dtype=np.int64)
        np.cumsum(freq, axis=1, out=self.cum[:, 1:])
        self.slot = np.repeat(np.tile(np.arange(A), C), freq.reshape(-1)).reshape(C, M)

    @property
    def shape(self) -> tuple[int, int]:
        return self.freq.shape

    @staticmethod
    def from_counts(counts: np.ndarray) -> "Tables":
        """Tables by :func:`normalize` (float arithmetic; format version 1 files)."""
        return Tables(np.stack([normalize(row) for row in np.asarray(counts)]))

    @staticmethod
    def from_weights(weights: np.ndarray) -> "Tables":
        """Tables by :func:`normalize_int` (integers; format versions ≥ 2), every row at once
        (:func:`normalize_int_rows`)."""
        return Tables(normalize_int_rows(weights))

    def bits(self, ctx: np.ndarray, sym: np.ndarray) -> np.ndarray:
        """Ideal code length in bits of each (context, symbol) (inf where the frequency is 0)."""
        f = self.freq[ctx, sym].astype(np.float64)
        with np.errstate(divide="ignore"):
            return PROB_BITS - np.log2(f)

    def to_bytes(self) -> bytes:
        """zlib of the (C, A) frequencies as little-endian u16 (M fits 13 bits)."""
        return zlib.compress(self.freq.astype("<u2").tobytes(), 9)

    @staticmethod
    def from_bytes(data: bytes, contexts: int, alphabet: int, name: str) -> "Tables":
        want = contexts * alphabet * 2
        try:
            d = zlib.decompressobj()
            raw = d.decompress(bytes(data), want + 1)
        except zlib.error as e:
            raise FormatError(f"{name}: rANS tables are not a valid stream ({e})") from None
        if len(raw) != want or not d.eof or d.unused_data:
            raise FormatError(f"{name}: rANS tables hold {len(raw)} bytes, expected {want}")
        freq = np.frombuffer(raw, dtype="<u2").astype(np.int64).reshape(contexts, alphabet)
        if (freq.sum(axis=1) != M).any():
            raise FormatError(f"{name}: a rANS table does not sum to {M}")
        return Tables(freq)


def encode_lanes(ctx: np.ndarray, sym: np.ndarray, lengths: np.ndarray, tables: Tables,
                 chunk: int = 4096, back: np.ndarray | None = None) -> list[bytes]:
    """Encode S streams at once.

    Args:
        ctx, sym: (S, K) int arrays, row i's first lengths[i] entries are stream i's
            (context, symbol) pairs in decode order (the rest is ignored).
        lengths: (S,) symbols per stream.
        back: (S,) values R < L carried by each stream's start state (default 0).

    Returns:
        S byte strings.

    Raises:
        ValueError: a symbol whose frequency is 0 in its context's table.
    """
    S = len(lengths)
    out: list[bytes] = [b""] * S
    if S == 0:
        return out
    lengths = np.asarray(lengths, dtype=np.int64)
    C, A = tables.freq.shape
    # freq << 16 | cum per (ctx, sym) in one int32 (freq ≤ M = 2^12, cum < M): 4 bytes a cell
    fc_t = ((tables.freq << 16) | tables.cum[:, :A]).astype(np.int32).reshape(-1)
    for a in range(0, S, chunk):
        idx = np.arange(a, min(S, a + chunk))
        order = idx[np.argsort(-lengths[idx], kind="stable")]        # active lanes form a prefix
        ln = lengths[order]
        K = int(ln[0]) if ln.size else 0
        n = order.size
        ci, si = ctx[order, :K], sym[order, :K]                         # (n, K), the callers' dtypes
        valid = np.arange(K)[None, :] < ln[:, None]
        if (((ci < 0) | (ci >= C) | (si < 0) | (si >= A)) & valid).any():
            raise ValueError("a context or symbol outside the tables")
        cell = ci.astype(np.int32)                                     # (ctx·A + sym), 0 where unused
        del ci
        cell *= A
        cell += si
        del si
        cell[~valid] = 0
        # step-major: row k holds every lane's k-th symbol (contiguous slices per step)
        cell = np.ascontiguousarray(cell.T)                            # (K, n)
        fc = fc_t[cell]
        del cell
        if (((fc >> 16) == 0) & valid.T).any():
            raise ValueError("a symbol with frequency 0 in its context cannot be coded")
        del valid
        cnt = np.searchsorted(-ln, -np.arange(K), side="left").tolist()  # lanes with ln > k: the first m
        cap = 2 * K + STATE_BYTES
        buf = np.zeros((n, cap), dtype=np.uint8)
        wp = np.full(n, cap, dtype=np.int64)
        x = np.full(n, L, dtype=np.int64) + (0 if back is None else np.asarray(back, np.int64)[order])
        rows = np.arange(n)
        for k in range(K - 1, -1, -1):
            m = cnt[k]
            if m == 0:
                continue
            w = fc[k, :m]
            f = (w >> 16).astype(np.int64)
            xm = x[:m]
            xmax = _XMAX_SCALE * f
            for _ in range(2):                                     # at most two bytes out per symbol
                e = xm >= xmax
                if not e.any():
                    break
                r = rows[:m][e]
                wp[r] -= 1
                buf[r, wp[r]] = (xm[e] & 255).astype(np.uint8)
                xm[e] >>= 8
            q, rem = np.divmod(xm, f)
            x[:m] = (q << PROB_BITS) + rem + (w & 0xFFFF)
        wp -= STATE_BYTES                                          # flush: x little-endian first
        sh = 8 * np.arange(STATE_BYTES)
        buf[rows[:, None], wp[:, None] + np.arange(STATE_BYTES)] = ((x[:, None] >> sh) & 255).astype(np.uint8)
        for i, o in enumerate(order.tolist()):
            out[o] = buf[i, wp[i]:].tobytes()
    return out


class LaneDecoder:
    """Decode many streams in step (numpy or torch): lane i reads ``buf`` from ``starts[i]``.

    ``buf`` must hold 8 readable bytes past the furthest stream end; reads are clamped to the
    buffer, and :meth:`check` reports lanes that read outside their own stream or did not end
    in the initial state.
    """

    def __init__(self, xp, buf, starts, tables: Tables, tabs=None):
        self.xp, self.buf = xp, buf
        self.ptr = starts + STATE_BYTES
        self.x = xp.cast(xp.word(buf, starts, STATE_BYTES), xp.int64)
        self.top = int(buf.shape[0]) - 1
        if isinstance(buf, np.ndarray) and tabs is None:
            self.t = None
            self.slot, self.fc, self.A = numpy_tables(tables)
        else:
            self.t = tabs or device_tables(xp, tables)

    def step(self, lanes, ctx):
        """Decode one symbol in each lane of ``lanes`` (indices) with contexts ``ctx``; returns
        the symbols (int64)."""
        if self.t is None:
            return self._step_numpy(lanes, ctx)
        t, xp = self.t, self.xp
        x = self.x[lanes]
        slot = x & (M - 1)
        s = t["slot"][ctx, slot]
        x = t["freq"][ctx, s] * (x >> PROB_BITS) + slot - t["cum"][ctx, s]
        p = self.ptr[lanes]
        for _ in range(2):                     # at most two bytes in per symbol
            need = x < L
            b = xp.cast(self.buf[p.clip(0, self.top)], xp.int64)
            x = xp.where(need, (x << 8) | b, x)
            p = p + xp.cast(need, xp.int64)
        self.x[lanes] = x
        self.ptr[lanes] = p
        return s

    def _step_numpy(self, lanes, ctx):
        """:meth:`step` in numpy with fewer, narrower passes (the same integers): the slot
        look-up in bytes, frequency and start of a symbol in one int64 word."""
        x = self.x[lanes]
        slot = x & (M - 1)
        ctx = np.asarray(ctx)
        s = self.slot[ctx * M + slot] if self.slot.ndim == 1 else self.slot[ctx, slot]
        fc = self.fc[ctx * self.A + s]                      # freq << 32 | cum
        x = (fc >> 32) * (x >> PROB_BITS) + slot - (fc & 0xFFFFFFFF)
        p = self.ptr[lanes]
        top, buf = self.top, self.buf
        for _ in range(2):                                  # at most two bytes in per symbol
            need = x < L
            x = np.where(need, (x << 8) | buf[np.minimum(p, top)], x)
            p += need
        self.x[lanes] = x
        self.ptr[lanes] = p
        return s.astype(np.int64)

    def check(self, ends, back_bits=0):
        """Bool per lane: the stream is well-formed (read exactly to ``ends``, and its final
        state is L + R with R < 2^back_bits; ``back_bits`` an int or one per lane)."""
        r = self.x - L
        return (r >= 0) & (r < (1 << back_bits)) & (self.ptr == ends)

    def back(self):
        """Each lane's R (the raw bits its start state carried), valid after :meth:`check`."""
        return self.x - L


def device_tables(xp, tables: Tables) -> dict:
    """The tables as backend arrays (flat, so one gather per look-up)."""
    return {"slot": xp.asarray(tables.slot), "freq": xp.asarray(tables.freq), "cum": xp.asarray(tables.cum)}


def numpy_tables(tables: Tables):
    """(slot look-up flat (C·M,) uint8 — or (C, M) int64 for alphabets over 256 —, freq << 32 |
    cum flat (C·A,) int64, A) for :meth:`LaneDecoder._step_numpy`, cached on the tables."""
    got = getattr(tables, "_numpy_lanes", None)
    if got is None:
        C, A = tables.freq.shape
        slot = tables.slot.astype(np.uint8).reshape(-1) if A <= 256 else tables.slot
        fc = ((tables.freq << 32) | tables.cum[:, :A]).reshape(-1)
        got = tables._numpy_lanes = (slot, fc, A)
    return got


def slot_bytes(tables: Tables) -> list:
    """Per context, the slot → symbol look-up as bytes (alphabets up to 256), cached."""
    if getattr(tables, "_slot_bytes", None) is None:
        if tables.freq.shape[1] > 256:
            tables._slot_bytes = tables.slot.tolist()
        else:
            tables._slot_bytes = [bytes(row) for row in tables.slot.astype(np.uint8)]
    return tables._slot_bytes


def scalar_tables(tables: Tables) -> tuple:
    """(per context: slot → symbol bytes, frequency list, cum list) of ``tables`` for the
    plain-Python decoders (Python ints below 2^30: CPython's one-digit ints), built once per
    table set and cached on it."""
    if getattr(tables, "_lists", None) is None:
        tables._lists = (tables.freq.tolist(), tables.cum.tolist())
    return (slot_bytes(tables),) + tables._lists


def scalar_step(slot_t, freq_t, cum_t, ctx: int, x: int, p: int, data) -> tuple[int, int, int]:
    """One rANS decode step on Python ints, for the plain-Python parsers' rare symbols (their
    common ones inline it): context ``ctx`` of per-context tables (slot → symbol bytes,
    frequency and cum lists), state ``x`` at byte ``p`` of ``data``: (symbol, x, p) after it.
    A read past ``data`` raises IndexError (the callers make it a FormatError)."""
    sl = x & (M - 1)
    s = slot_t[ctx][sl]
    x = freq_t[ctx][s] * (x >> PROB_BITS) + sl - cum_t[ctx][s]
    while x < L:
        x = (x << 8) | data[p]
        p += 1
    return s, x, p


class ScalarDecoder:
    """One stream in plain Python ints (the reference; fast for short streams)."""

    def __init__(self, data: bytes, tables: Tables):
        if len(data) < STATE_BYTES:
            raise FormatError(f"rANS stream shorter than its {STATE_BYTES}-byte state")
        self.data, self.t = data, tables
        self.x = int.from_bytes(data[:STATE_BYTES], "little")
        self.ptr = STATE_BYTES
        self.slot, self.freq, self.cum = scalar_tables(tables)

    def get(self, ctx: int) -> int:
        try:
            s, self.x, self.ptr = scalar_step(self.slot, self.freq, self.cum, ctx, self.x, self.ptr, self.data)
        except IndexError:
            raise FormatError("rANS stream reads past its end") from None
        return s

    def done(self, end: int, back_bits: int = 0) -> bool:
        """Read exactly to ``end`` and the final state is L + R with R < 2^back_bits."""
        return 0 <= self.x - L < (1 << back_bits) and self.ptr == end
