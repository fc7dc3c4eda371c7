"""The ``tx`` profile's side sections, read once when a file is opened (zlib streams; zig-zag
LEB128 varints for signed integers).

- ``tx.maps``: see :mod:`rlfc.txmaps` (rANS-coded).
- ``tx.thumbs``: per intra view (in key order) the thumbnail levels (ty × tx × P, raster,
  planes last) as varints of differences: row 0 from the left neighbour (0 before the first),
  other rows from the neighbour above.
- ``tx.index``: the byte lengths of the key views' row streams (key order, rows top to
  bottom, a row's ``key_split`` streams left to right) as varints; then a bitmap over (view,
  block) (view-major, LSB first; zero for key views) of the other views' blocks that have a
  stream, then those streams' lengths as varints, in the order of ``tx.blocks``.
- ``tx.blocks``: the streams: each key view as ``key_split`` streams per row of blocks (key
  order, rows top to bottom; a stream parses like one block whose tbs are its blocks' tbs in
  order), then the other views' block streams location by location (raster), views ascending.
"""
from __future__ import annotations

import zlib

import numpy as np

from formats.errors import FormatError

MAX_VARINT_BYTES = 10


def varints(values: np.ndarray) -> bytes:
    """Zig-zag LEB128 of int64 values (vectorized)."""
    v = np.asarray(values, dtype=np.int64).reshape(-1)
    u = ((v << 1) ^ (v >> 63)).view(np.uint64)
    nb = np.ones(u.size, np.int64)
    for k in range(1, MAX_VARINT_BYTES):
        nb += u >= (np.uint64(1) << np.uint64(7 * k))
    out = np.zeros(int(nb.sum()), np.uint8)
    start = np.cumsum(nb) - nb
    for k in range(MAX_VARINT_BYTES):
        m = nb > k
        if not m.any():
            break
        byte = ((u[m] >> np.uint64(7 * k)) & np.uint64(127)).astype(np.uint8)
        out[start[m] + k] = byte | np.where(nb[m] > k + 1, 128, 0).astype(np.uint8)
    return out.tobytes()


def unvarints(data, count: int, what: str) -> np.ndarray:
    """Inverse of :func:`varints`: exactly ``count`` values filling ``data``."""
    b = np.frombuffer(bytes(data), np.uint8)
    if b.size == count and not (b >= 128).any():     # every value one byte (most sections): zig-zag only
        x = b.astype(np.int64)
        return (x >> 1) ^ -(x & 1)
    ends = np.flatnonzero(b < 128)
    if ends.size != count or (count and ends[-1] != b.size - 1) or (count == 0 and b.size):
        raise FormatError(f"{what}: expected {count} varints in {b.size} bytes")
    if count:
        starts = np.concatenate([[0], ends[:-1] + 1])
        lens = ends - starts + 1
        if (lens > MAX_VARINT_BYTES).any():
            raise FormatError(f"{what}: a varint is longer than {MAX_VARINT_BYTES} bytes")
        # every value's first byte at once; the later bytes only for the values that have them
        # (few: most values in these sections are small), not masked passes over every value
        u = (b[starts] & 127).astype(np.uint64)
        more = np.flatnonzero(lens > 1)
        for k in range(1, MAX_VARINT_BYTES):
            if not more.size:
                break
            u[more] |= (b[starts[more] + k].astype(np.uint64) & np.uint64(127)) << np.uint64(7 * k)
            more = more[lens[more] > k + 1]
    else:
        u = np.zeros(0, np.uint64)
    v = (u >> np.uint64(1)).view(np.int64) ^ -(u & np.uint64(1)).view(np.int64)
    return v


def inflate(data, limit: int, what: str) -> bytes:
    """A zlib stream of at most ``limit`` bytes (no trailing data)."""
    try:
        d = zlib.decompressobj()
        raw = d.decompress(bytes(data), limit + 1)
    except zlib.error as e:
        raise FormatError(f"{what} is not a valid zlib stream ({e})") from None
    if len(raw) > limit or not d.eof or d.unused_data:
        raise FormatError(f"{what} is malformed or larger than its {limit}-byte bound")
    return raw


def pack_thumbs(levels: np.ndarray) -> bytes:
    """(n, ty, tx, P) int thumbnail levels → section bytes."""
    d = levels.astype(np.int64).copy()
    if d.size:
        d[:, 1:] = levels[:, 1:] - levels[:, :-1]
        d[:, 0, 1:] = levels[:, 0, 1:] - levels[:, 0, :-1]
    return zlib.compress(varints(d), 9)


def unpack_thumbs(data, shape: tuple, what: str) -> np.ndarray:
    count = int(np.prod(shape))
    d = unvarints(inflate(data, count * MAX_VARINT_BYTES, what), count, what).reshape(shape)
    if count:
        d[:, 0] = np.cumsum(d[:, 0], axis=1)
        d = np.cumsum(d, axis=1)
        if np.abs(d).max() > (1 << 24):
            raise FormatError(f"{what}: a thumbnail level is out of range")
    return d


def pack_index(key_lengths: np.ndarray, coded: np.ndarray, lengths: np.ndarray) -> bytes:
    """Key row stream lengths (n_keys·nby·key_split,), the other views' coded blocks (N0, nloc) bool and
    their stream lengths in ``tx.blocks`` order."""
    return zlib.compress(varints(key_lengths) + np.packbits(coded.reshape(-1), bitorder="little").tobytes()
                         + varints(lengths), 9)


def unpack_index(data, n_keys: int, nby: int, n_views: int, nloc: int, is_key: np.ndarray, what: str):
    """→ (key row stream lengths (n_keys, nby: the streams per key), coded (N0, nloc) bool, block stream lengths)."""
    nb = (n_views * nloc + 7) // 8
    raw = inflate(data, (n_keys * nby + n_views * nloc) * MAX_VARINT_BYTES + nb, what)
    b = np.frombuffer(raw, np.uint8)
    ends = np.flatnonzero(b < 128)
    nk = n_keys * nby
    if ends.size < nk:
        raise FormatError(f"{what}: too short for {nk} key row lengths")
    cut = int(ends[nk - 1]) + 1 if nk else 0
    key_lengths = unvarints(raw[:cut], nk, what).reshape(n_keys, nby)
    if len(raw) < cut + nb:
        raise FormatError(f"{what}: too short for the coded-block bitmap")
    coded = np.unpackbits(np.frombuffer(raw[cut:cut + nb], np.uint8), bitorder="little")[:n_views * nloc]
    coded = coded.astype(bool).reshape(n_views, nloc)
    if coded[is_key].any():
        raise FormatError(f"{what}: the bitmap marks a block of a key view")
    lengths = unvarints(raw[cut + nb:], int(coded.sum()), what)
    for lv in (key_lengths, lengths):
        if lv.size and ((lv < 3).any() or (lv > 1 << 28).any()):   # a stream holds at least its 3-byte state
            raise FormatError(f"{what}: a stream length is out of range")
    return key_lengths, coded, lengths


def stream_order(coded: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(view, location) of each non-key block stream in ``tx.blocks`` order (after the key rows)."""
    loc, v = np.nonzero(coded.T)                      # location-major, views ascending
    return v.astype(np.int64), loc.astype(np.int64)
