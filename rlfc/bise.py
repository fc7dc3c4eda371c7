"""Bounded Integer Sequence Encoding, bit-exact with ASTC's integer sequence encoding.

A sequence of ``count`` integers in ``[0, N-1]`` (N one of the 21 ASTC ranges) is written
LSB-first from bit 0 of a zeroed buffer: plain ranges as n-bit fields; trit ranges in groups
of 5 values (n low bits each, interleaved with an 8-bit packed trit code); quint ranges in
groups of 3 (7-bit packed quint code). See :mod:`rlfc.bise_tables`.

Everything here is vectorized numpy: the batched forms handle many blocks in one call with no
Python loop over values or blocks (the grouped forms loop over the at most 21 distinct ranges).
Decoding gathers unaligned little-endian words at each field's byte offset; the decode kernel
(:func:`decode_words`) is written once for numpy and torch.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from formats.errors import ParameterError, TruncatedError

from .xp import NUMPY, shared
from .bise_tables import (QUINT_CODE, QUINT_DIGITS, QUINT_LAYOUT, RANGE_INDEX, RANGE_VALUES, RANGES, TRIT_CODE,
                          TRIT_DIGITS, TRIT_LAYOUT)

__all__ = ["RANGE_VALUES", "bit_length", "byte_length", "smallest_range", "encode", "decode", "encode_batch",
           "decode_batch", "decode_at", "encode_grouped", "decode_grouped"]

#: Bytes of slack a buffer passed to :func:`decode_at` needs after its last encoded byte.
SLACK = 8


def _check_range(n) -> tuple[int, int, int]:
    try:
        i = RANGE_INDEX[int(n)]
    except (KeyError, TypeError, ValueError):
        raise ParameterError(f"BISE range {n!r} is not an ASTC range (one of {', '.join(map(str, RANGE_VALUES))})") from None
    if int(n) != n:
        raise ParameterError(f"BISE range {n!r} is not an integer")
    _, bits, trits, quints = RANGES[i]
    return bits, trits, quints


def bit_length(count: int, n: int) -> int:
    """Bits used by ``count`` values in range ``n`` (ASTC's ``get_ise_sequence_bitcount``)."""
    bits, trits, quints = _check_range(n)
    count = int(count)
    if count < 0:
        raise ParameterError(f"count must be >= 0, got {count}")
    return count * bits + (-(-8 * count // 5) if trits else 0) + (-(-7 * count // 3) if quints else 0)


def byte_length(count: int, n: int) -> int:
    """Bytes used by ``count`` values in range ``n`` (bit length rounded up)."""
    return -(-bit_length(count, n) // 8)


def smallest_range(max_value) -> int | np.ndarray:
    """Smallest ASTC range N with ``max_value <= N - 1`` (scalar or array of values 0..255)."""
    mv = np.asarray(max_value)
    if (mv < 0).any() or (mv > 255).any():
        raise ParameterError(f"max value must be within 0..255 for a BISE range, got {mv.min()}..{mv.max()}")
    table = np.asarray(RANGE_VALUES)
    out = table[np.searchsorted(table, mv + 1)]
    return int(out) if out.ndim == 0 else out


def decode_at(buf: np.ndarray, starts, n: int, count: int) -> np.ndarray:
    """Decode many BISE blocks that start at given byte offsets of one buffer.

    Args:
        buf: 1-D uint8 array holding the blocks, with at least :data:`SLACK` readable bytes
            after the last encoded byte (zero or not: bits past a block's end are masked).
        starts: (nb,) byte offsets of the blocks (each block starts at bit 0 of its byte).
        n: ASTC range of every block.
        count: values per block.

    Returns:
        (nb, count) uint8 values.
    """
    _check_range(n)
    starts = np.asarray(starts, dtype=np.int64).reshape(-1)
    nb = starts.size
    if nb == 0 or count == 0:
        return np.zeros((nb, count), dtype=np.uint8)
    nbytes = -(-bit_length(count, n) // 8)
    if starts.min() < 0 or starts.max() + nbytes + SLACK - 1 > buf.size:
        raise TruncatedError(f"BISE buffer of {buf.size} bytes is too short for {nb} blocks of {count} values "
                             f"in range {n} ({nbytes} bytes each + {SLACK} slack) at the given offsets")
    return decode_words(NUMPY, np.ascontiguousarray(buf, dtype=np.uint8), starts, n, count)


def decode_words(xp, buf, starts, n: int, count: int):
    """The BISE decode kernel, for numpy or torch (``xp`` from :mod:`rlfc.xp`).

    Bounds are the caller's job (``buf`` needs :data:`SLACK` bytes after the last block).

    Args:
        buf: 1-D uint8 array/tensor; starts: (nb,) int64 byte offsets; n: ASTC range.

    Returns:
        (nb, count) values (uint8 on numpy; integer tensors on torch).
    """
    bits, trits, quints = _check_range(n)
    if not (trits or quints):
        # plain range: one unaligned 16-bit gather per value (a field spans <= 8 + 7 bits)
        pos = np.arange(count, dtype=np.int64) * bits
        w = xp.word(buf, starts[:, None] + xp.asarray(pos >> 3)[None, :], 2)
        return xp.cast((w >> xp.cast(xp.asarray(pos & 7), w.dtype)[None, :]) & ((1 << bits) - 1), xp.uint8)
    gpos, gmask, fields, group = _group_layout(bits, trits, count, bit_length(count, n))
    gsize = 5 * bits + 8 if trits else 3 * bits + 7
    # trit/quint groups: one unaligned gather of <= 7 bytes per group (a group spans <= 45 bits)
    word = xp.word(buf, starts[:, None] + xp.asarray(gpos >> 3)[None, :], 7)
    word = xp.narrow((word >> xp.cast(xp.asarray(gpos & 7), word.dtype)[None, :]) &
                     xp.cast(xp.asarray(gmask), word.dtype)[None, :], gsize)
    code = None
    ms = [None] * group
    for kind, slot, off, width in fields:   # fixed ~10 bit fields of the group layout, all blocks at once
        val = (word >> off) & ((1 << width) - 1)
        if kind == "m":
            ms[slot] = xp.cast(val, xp.uint8)
        else:
            code = val << slot if code is None else code | (val << slot)
    digits = xp.take_rows(_digit_table(xp, trits), code)                       # (nb, G, group) uint8
    if bits:
        digits = (digits << bits) | xp.stack(ms, -1)
    return digits.reshape(starts.shape[0], -1)[:, :count]


def _digit_table(xp, trits: bool):
    """TRIT_DIGITS / QUINT_DIGITS (uint8) in the backend, cached per backend and device."""
    key = (xp.name, str(getattr(xp, "device", "")), trits)
    if key not in _DIGITS:
        _DIGITS[key] = shared(xp.asarray(TRIT_DIGITS if trits else QUINT_DIGITS))
    return _DIGITS[key]


_DIGITS: dict = {}


@lru_cache(maxsize=512)
def _group_layout(bits: int, trits: int, count: int, total: int):
    """Per-group bit offsets for trit/quint blocks: (group starts (G,), valid-bit masks (G,), fields)."""
    group, gsize, layout = (5, 5 * bits + 8, TRIT_LAYOUT) if trits else (3, 3 * bits + 7, QUINT_LAYOUT)
    ng = -(-count // group)
    gpos = np.arange(ng, dtype=np.int64) * gsize
    valid = np.minimum(total - gpos, gsize).astype(np.uint64)
    gmask = ((np.uint64(1) << valid) - np.uint64(1)).astype(np.uint64)
    fields, pos = [], 0
    for f in layout:                      # (kind, value slot or code bit, offset in group, width)
        width = bits if f[0] == "m" else f[2]
        fields.append((f[0], f[1], pos, width))
        pos += width
    return gpos, gmask, tuple(fields), group


def _as_values(values, n: int) -> np.ndarray:
    arr = np.asarray(values)
    if arr.dtype == object or arr.dtype.kind not in "iub":
        if arr.size == 0:
            arr = arr.astype(np.int64)
        elif arr.dtype.kind == "f" and np.all(np.isfinite(arr)) and np.all(arr == np.round(arr)):
            raise ParameterError(f"BISE values must have an integer dtype, got {arr.dtype}")
        else:
            raise ParameterError(f"BISE values must be integers, got dtype {arr.dtype}")
    if arr.size and (arr.min() < 0 or arr.max() >= n):
        raise ParameterError(f"BISE values must lie in [0, {n - 1}] for range {n}; got {arr.min()}..{arr.max()}")
    return arr.astype(np.uint32)


def encode_batch(values, n: int) -> np.ndarray:
    """Encode a 2-D array of equal-length blocks, each as its own BISE stream.

    Args:
        values: (nb, count) integers in [0, n-1].
        n: ASTC range.

    Returns:
        (nb, byte_length(count, n)) uint8; row i is block i's bytes (unused high bits zero).
    """
    bits, trits, quints = _check_range(n)
    v = _as_values(values, n)
    if v.ndim != 2:
        raise ParameterError(f"encode_batch expects (blocks, count) values, got shape {v.shape}")
    nb, count = v.shape
    total = bit_length(count, n)
    nbytes = -(-total // 8)
    if nb == 0 or count == 0:
        return np.zeros((nb, nbytes), dtype=np.uint8)
    sh = np.arange(bits, dtype=np.uint32)
    if not (trits or quints):
        bitmat = ((v[:, :, None] >> sh) & 1).astype(np.uint8).reshape(nb, count * bits)
    else:
        group, layout, code_bits = (5, TRIT_LAYOUT, 8) if trits else (3, QUINT_LAYOUT, 7)
        ng = -(-count // group)
        vp = np.zeros((nb, ng * group), dtype=np.uint32)
        vp[:, :count] = v
        vp = vp.reshape(nb, ng, group)
        dig = vp >> bits
        radix = 3 if trits else 5
        idx = np.zeros((nb, ng), dtype=np.int64)
        for k in range(group - 1, -1, -1):   # Horner over the 3 or 5 digit slots of a group
            idx = idx * radix + dig[:, :, k]
        code = (TRIT_CODE if trits else QUINT_CODE)[idx].astype(np.uint32)             # (nb, G)
        mbits = ((vp[..., None] >> sh) & 1).astype(np.uint8)                             # (nb, G, group, bits)
        cbits = ((code[..., None] >> np.arange(code_bits, dtype=np.uint32)) & 1).astype(np.uint8)  # (nb, G, code_bits)
        cols = [mbits[:, :, f[1], :] if f[0] == "m" else cbits[:, :, f[1]:f[1] + f[2]] for f in layout]
        bitmat = np.concatenate(cols, axis=2).reshape(nb, -1)[:, :total]
    out_bits = np.zeros((nb, nbytes * 8), dtype=np.uint8)
    out_bits[:, :total] = bitmat[:, :total]
    return np.packbits(out_bits, axis=1, bitorder="little")


def decode_batch(data, n: int, count: int) -> np.ndarray:
    """Inverse of :func:`encode_batch`: (nb, nbytes) uint8 → (nb, count) uint8 values."""
    arr = np.asarray(data, dtype=np.uint8)
    if arr.ndim != 2:
        raise ParameterError(f"decode_batch expects (blocks, bytes) data, got shape {arr.shape}")
    need = byte_length(count, n)
    if arr.shape[1] < need:
        raise TruncatedError(f"BISE blocks of {arr.shape[1]} bytes are too short for {count} values in range {n} "
                             f"({need} bytes needed)")
    nb, stride = arr.shape
    buf = np.zeros(nb * stride + SLACK, dtype=np.uint8)
    buf[:nb * stride] = arr.reshape(-1)
    return decode_at(buf, np.arange(nb, dtype=np.int64) * stride, n, count)


def encode(values, n: int) -> bytes:
    """Encode one sequence of integers in [0, n-1] (n an ASTC range) to bytes."""
    v = np.asarray(values)
    if v.ndim != 1:
        raise ParameterError(f"encode expects a 1-D sequence, got shape {v.shape}")
    return encode_batch(v.reshape(1, -1) if v.size else np.zeros((1, 0), dtype=np.int64), n)[0].tobytes()


def decode(data, n: int, count: int) -> np.ndarray:
    """Decode ``count`` values in range ``n`` from the start of ``data`` (bytes-like).

    Returns:
        (count,) uint8 array.

    Raises:
        TruncatedError: ``data`` is shorter than ``byte_length(count, n)``.
    """
    count = int(count)
    if count < 0:
        raise ParameterError(f"count must be >= 0, got {count}")
    need = byte_length(count, n)
    raw = np.frombuffer(bytes(data), dtype=np.uint8)
    if raw.size < need:
        raise TruncatedError(f"BISE data of {raw.size} bytes is too short for {count} values in range {n} "
                             f"({need} bytes needed)")
    buf = np.zeros(need + SLACK, dtype=np.uint8)
    buf[:need] = raw[:need]
    return decode_at(buf, np.zeros(1, dtype=np.int64), n, count)[0]


def encode_grouped(values, ranges) -> tuple[np.ndarray, np.ndarray]:
    """Encode equal-length blocks with a range per block, grouped by range internally.

    Args:
        values: (nb, count) integers; row i must lie in [0, ranges[i]-1].
        ranges: (nb,) ASTC ranges.

    Returns:
        (data, offsets): data is one uint8 array with the blocks in input order, block i at
        ``data[offsets[i]:offsets[i+1]]``; offsets is (nb+1,) int64.
    """
    v = np.asarray(values)
    r = np.asarray(ranges).reshape(-1)
    if v.ndim != 2 or v.shape[0] != r.size:
        raise ParameterError(f"values {v.shape} and ranges {r.shape} disagree")
    count = v.shape[1]
    sizes = np.zeros(r.size, dtype=np.int64)
    uniq = np.unique(r)
    for n in uniq.tolist():
        sizes[r == n] = byte_length(count, n)
    offsets = np.concatenate([[0], np.cumsum(sizes)])
    data = np.zeros(int(offsets[-1]), dtype=np.uint8)
    for n in uniq.tolist():
        sel = np.flatnonzero(r == n)
        enc = encode_batch(v[sel], n)
        if enc.shape[1]:
            data[offsets[sel][:, None] + np.arange(enc.shape[1])] = enc
    return data, offsets


def decode_grouped(buf, starts, ranges, count: int) -> np.ndarray:
    """Decode blocks with a range per block from one buffer (see :func:`decode_at` for slack).

    Args:
        buf: 1-D uint8 buffer; starts: (nb,) byte offsets; ranges: (nb,) ASTC ranges.

    Returns:
        (nb, count) uint8 values.
    """
    r = np.asarray(ranges).reshape(-1)
    starts = np.asarray(starts, dtype=np.int64).reshape(-1)
    out = np.empty((r.size, count), dtype=np.uint8)
    for n in np.unique(r).tolist():
        sel = np.flatnonzero(r == n)
        out[sel] = decode_at(buf, starts[sel], n, count)
    return out
