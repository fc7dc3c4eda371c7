"""Residual block layout: per-block modes, runs gathered per spatial location behind a
block-offset table, and the vectorized decode of many (node, location) blocks at once.

Blocks section ("rlfc.blocks"): one run per block location (by·nbx + bx), at
``index[loc]..index[loc+1]`` (empty when equal). A run is::

    bitmap   ceil(n_nodes/8) bytes, bit g (LSB-first) set if residual node g has a block here;
             nodes are numbered in BFS order (level H-1 first, then down to the views)
    headers  one per present block, in node order, hs = off_bytes + P + P·min_bytes bytes:
             payload offset from the run start (unsigned LE), P mode bytes, P minimums (signed LE)
    payloads each block's planes back to back, each byte-aligned

Plane modes (on-wire values; do not reorder):
    0..20   BISE range RANGE_VALUES[mode] of (q - min), B·B values
    21      constant plane (q == min everywhere): no payload
    32+k    plain k-bit values (q - min), k = 9..31, for spans wider than 256
    255     (in plane 0 only) raw block: the level's key view pixels at the input bit depth,
            all channels, interleaved, B·B·C samples (uint8 or little-endian uint16)
The section ends with 8 zero bytes so that decoders may read 64-bit words past the last block.
"""
from __future__ import annotations

import zlib

import numpy as np

from formats.errors import ChecksumError, FormatError

from . import bise
from .bise_tables import RANGE_VALUES
from .kernels import MODE_CONST, MODE_PLAIN, MODE_RAW, plain_values
from .xp import NUMPY

PAD = 8
_RANGES = np.asarray(RANGE_VALUES, dtype=np.int64)
_POPCOUNT = np.array([bin(i).count("1") for i in range(256)], dtype=np.int64)


def pack_index(index: np.ndarray) -> bytes:
    """(nloc + 1,) run start offsets → zlib-compressed u32 run lengths (the dcp index coding:
    the whole index is read once at open, so compressing it costs random access nothing)."""
    return zlib.compress(np.diff(index).astype("<u4").tobytes(), 9)


def inflate_exact(data: bytes, want: int, name: str, section: str, what: str) -> bytes:
    """A zlib stream that must inflate to exactly ``want`` bytes (``what``: what they hold);
    anything else (bad stream, short, long, trailing bytes) is a FormatError naming the file
    ``name`` and the section."""
    try:
        d = zlib.decompressobj()
        raw = d.decompress(data, want + 1)
    except zlib.error as e:
        raise FormatError(f"{name}: section {section!r} is not a valid stream ({e})") from None
    if len(raw) != want or not d.eof or d.unused_data:
        raise FormatError(f"{name}: section {section!r} holds {len(raw)} bytes of {what}, expected {want}")
    return raw


def unpack_index(data: bytes, nloc: int, name: str) -> np.ndarray:
    """Inverse of :func:`pack_index` → (nloc + 1,) int64 offsets; bad data raises FormatError."""
    raw = inflate_exact(data, 4 * nloc, name, "rlfc.index", "run lengths")
    return np.concatenate([[0], np.cumsum(np.frombuffer(raw, dtype="<u4").astype(np.int64))])


def plane_modes(mn: np.ndarray, mx: np.ndarray) -> np.ndarray:
    """Smallest mode for planes with value span mx - mn (int arrays) → uint8 modes."""
    span = (mx.astype(np.int64) - mn.astype(np.int64))
    idx = np.searchsorted(_RANGES, np.minimum(span, 255) + 1)
    k = np.maximum(np.ceil(np.log2(np.maximum(span, 1) + 1)).astype(np.int64), 9)
    mode = np.where(span == 0, MODE_CONST, np.where(span <= 255, idx, MODE_PLAIN + k))
    return mode.astype(np.uint8)


def mode_bytes_table(count: int) -> np.ndarray:
    """(256,) payload bytes of one plane of ``count`` values per mode (raw handled apart)."""
    t = np.zeros(256, dtype=np.int64)
    for i, n in enumerate(RANGE_VALUES):
        t[i] = bise.byte_length(count, n)
    for k in range(1, 32):
        t[MODE_PLAIN + k] = -(-count * k // 8)
    return t


def pack_plain(values: np.ndarray, k: int) -> np.ndarray:
    """(nb, count) unsigned ints < 2^k → (nb, ceil(count·k/8)) LSB-first plain k-bit fields."""
    nb, count = values.shape
    bits = ((values.astype(np.uint64)[:, :, None] >> np.arange(k, dtype=np.uint64)) & np.uint64(1)).astype(np.uint8)
    nbytes = -(-count * k // 8)
    out = np.zeros((nb, nbytes * 8), dtype=np.uint8)
    out[:, :count * k] = bits.reshape(nb, count * k)
    return np.packbits(out, axis=1, bitorder="little")


def _le_bytes(x: np.ndarray, nbytes: int) -> np.ndarray:
    """(n,) ints → (n, nbytes) little-endian two's-complement bytes."""
    return np.ascontiguousarray(x.astype("<i8")).view(np.uint8).reshape(-1, 8)[:, :nbytes]


def _from_le(b: np.ndarray, signed: bool) -> np.ndarray:
    """(n, k) little-endian bytes → (n,) int64."""
    n, k = b.shape
    v = (b.astype(np.int64) << (8 * np.arange(k, dtype=np.int64))).sum(axis=1)
    if signed:
        v = np.where(v >= 1 << (8 * k - 1), v - (1 << (8 * k)), v)
    return v


def pack_runs(g: np.ndarray, loc: np.ndarray, q: np.ndarray, raw: np.ndarray, raw_px: np.ndarray,
              n_nodes: int, n_loc: int, bps: int) -> tuple[np.ndarray, np.ndarray, dict]:
    """Pack kept blocks into per-location runs.

    Args:
        g: (K,) BFS node ids; loc: (K,) location ids; no (g, loc) pair twice.
        q: (K, P, n) int32 quantization indices per plane (n = B·B).
        raw: (K,) bool, block stored raw; raw_px: (K, n·C) raw samples (rows used where raw).
        n_nodes: residual nodes in the tree; n_loc: block locations; bps: bytes per raw sample.

    Returns:
        (index (n_loc+1,) uint32 byte offsets, blocks uint8 (ends with PAD zero bytes),
        layout dict: off_bytes, min_bytes, bitmap_bytes).
    """
    K, P, n = q.shape
    nbm = -(-n_nodes // 8)
    mn = q.min(axis=2) if n else np.zeros((K, P), np.int32)
    mx = q.max(axis=2) if n else np.zeros((K, P), np.int32)
    modes = plane_modes(mn, mx)
    modes[raw, 0] = MODE_RAW
    modes[raw, 1:] = MODE_CONST      # unused for raw blocks; written as "no payload"
    mn[raw] = 0
    table = mode_bytes_table(n)
    psize = table[modes]
    psize[raw, 0] = raw_px.shape[1] * bps
    psize[raw, 1:] = 0
    mabs = int(np.abs(mn).max()) if K else 0
    min_bytes = 2 if mabs < 2 ** 15 else 4
    order = np.lexsort((g, loc))
    g, loc, q, raw, modes, mn, psize = g[order], loc[order], q[order], raw[order], modes[order], mn[order], psize[order]
    raw_px = raw_px[order]
    per_loc = np.bincount(loc, minlength=n_loc)
    first = np.concatenate([[0], np.cumsum(per_loc)])[:-1]
    rank = np.arange(K) - first[loc]
    bsize = psize.sum(axis=1)
    loc_pay = np.bincount(loc, weights=bsize, minlength=n_loc).astype(np.int64)
    off_bytes = 2
    for _ in range(2):
        hs = off_bytes + P + P * min_bytes
        run_size = np.where(per_loc > 0, nbm + per_loc * hs + loc_pay, 0)
        if run_size.max(initial=0) < 65536:
            break
        off_bytes = 4
    hs = off_bytes + P + P * min_bytes
    index = np.concatenate([[0], np.cumsum(run_size)]).astype(np.int64)
    if index[-1] >= 2 ** 32:
        raise ValueError("blocks section over 4 GiB")
    blocks = np.zeros(int(index[-1]) + PAD, dtype=np.uint8)
    run0 = index[loc]
    # bitmaps
    nonempty = np.flatnonzero(per_loc)
    bm = np.zeros((n_loc, nbm * 8), dtype=np.uint8)
    bm[loc, g] = 1
    bmb = np.packbits(bm[nonempty], axis=1, bitorder="little")
    blocks[index[nonempty][:, None] + np.arange(nbm)] = bmb
    # payload offsets (relative to the run start)
    cum = np.cumsum(bsize) - bsize
    pay_rel = nbm + per_loc[loc] * hs + (cum - cum[first[loc]])
    hdr = np.concatenate([_le_bytes(pay_rel, off_bytes), modes,
                          _le_bytes(mn.reshape(-1), min_bytes).reshape(K, P * min_bytes)], axis=1)
    blocks[(run0 + nbm + rank * hs)[:, None] + np.arange(hs)] = hdr
    # plane payloads, grouped by mode
    pstart = run0[:, None] + pay_rel[:, None] + (np.cumsum(psize, axis=1) - psize)
    vals = q - mn[:, :, None]
    for m in np.unique(modes).tolist():
        if m == MODE_CONST:
            continue
        if m == MODE_RAW:
            sel = np.flatnonzero(raw)
            data = raw_px[sel].astype("<u2").view(np.uint8).reshape(len(sel), -1) if bps == 2 else raw_px[sel].astype(np.uint8)
            blocks[pstart[sel, 0][:, None] + np.arange(data.shape[1])] = data
            continue
        kk, cc = np.nonzero((modes == m) & ~raw[:, None])
        if m < MODE_CONST:
            enc = bise.encode_batch(vals[kk, cc], RANGE_VALUES[m])
        else:
            enc = pack_plain(vals[kk, cc].astype(np.int64), m - MODE_PLAIN)
        if enc.shape[1]:
            blocks[pstart[kk, cc][:, None] + np.arange(enc.shape[1])] = enc
    return index.astype(np.uint32), blocks, {"off_bytes": off_bytes, "min_bytes": min_bytes, "bitmap_bytes": nbm}


_VALID_MODE = np.zeros(256, bool)
_VALID_MODE[:MODE_CONST + 1] = True
_VALID_MODE[MODE_PLAIN + 1:MODE_PLAIN + 32] = True


#: largest stored value ``q − min`` of one plane per mode (raw and constant: 0)
_VMAX = np.zeros(256, dtype=np.int64)
_VMAX[:len(RANGE_VALUES)] = _RANGES - 1
_VMAX[MODE_PLAIN + 1:MODE_PLAIN + 32] = (1 << np.arange(1, 32)) - 1
#: the largest dequantized residual a block may carry (FORMAT.md); keeps every sum of a
#: residual chain (≤ 16 levels) exact in int32
MAX_RESIDUAL = 1 << 24
_VMAX_LIST = _VMAX.tolist()


def check_blocks(modes: np.ndarray, mins: np.ndarray, q16) -> None:
    """(S, P) modes and minimums of present blocks, (P,) quantizer steps: every mode defined
    (:func:`check_modes`) and every residual the header allows within ±MAX_RESIDUAL; else
    FormatError."""
    check_modes(modes)
    if q16 is None:
        return
    vmax = _VMAX[modes]
    qmax = np.maximum(np.abs(mins), np.abs(mins + vmax))          # |min| < 2^31: int64 is exact
    big = ((qmax * np.asarray(q16, np.int64) + 8) >> 4) > MAX_RESIDUAL
    big[modes[:, 0] == MODE_RAW] = False
    if big.any():
        raise FormatError(f"rlfc block header allows residuals beyond ±{MAX_RESIDUAL} (corrupt file)")


def check_modes(modes: np.ndarray) -> None:
    """(S, P) uint8 plane modes of present blocks: every mode defined, raw only in plane 0
    (and then the other planes "constant"); else FormatError."""
    raw = modes[:, 0] == MODE_RAW
    ok = _VALID_MODE[modes]
    ok[:, 0] |= raw
    if not ok.all() or (raw[:, None] & (modes[:, 1:] != MODE_CONST)).any():
        raise FormatError("rlfc block has an undefined plane mode (corrupt file)")


class BlockStore:
    """Random access to residual blocks.

    Args:
        index: (n_loc+1,) int64 run offsets.
        buf: uint8 blocks section (with PAD slack), or None with ``fetch`` given.
        planes: P; block: B; channels: C of raw blocks; bps: bytes per raw sample;
        layout: off_bytes, min_bytes, bitmap_bytes (from the file's config).
        verify: ``verify(starts, stops)`` checks the checksum chunks of byte ranges before use.
        n_nodes: residual nodes (bitmap bits at or beyond it must be zero); q16: (P,) quantizer
        steps (headers whose residuals could exceed ±MAX_RESIDUAL are refused).
    """

    def __init__(self, index: np.ndarray, buf: np.ndarray, planes: int, block: int, channels: int, bps: int,
                 layout: dict, verify=None, verify_span=None, n_nodes: int | None = None, q16=None):
        self.index = index.astype(np.int64)
        self.n_nodes, self.q16 = n_nodes, None if q16 is None else np.asarray(q16, np.int64)
        self._q16s = None if q16 is None else [int(q) for q in q16]
        self._high = 0 if n_nodes is None else (0xFF << (n_nodes - 8 * (layout["bitmap_bytes"] - 1))) & 0xFF
        self.buf = buf
        self.P, self.B, self.C, self.bps = planes, block, channels, bps
        self.off_bytes, self.min_bytes, self.nbm = layout["off_bytes"], layout["min_bytes"], layout["bitmap_bytes"]
        self.hs = self.off_bytes + planes + planes * self.min_bytes
        self.table = mode_bytes_table(block * block)
        self.verify = verify
        self.verify_span = verify_span
        if len(self.index) < 2 or (np.diff(self.index) < 0).any() or self.index[-1] + PAD > buf.size:
            raise ChecksumError("rlfc block-offset table is inconsistent with the blocks section")

    def raw_samples(self, xp, buf, pay):
        """Raw blocks' samples: (R,) payload offsets → (R, B·B, C) int64 (uint8 or u16 LE)."""
        n = self.B * self.B
        nb = n * self.C * self.bps
        byte = pay[:, None] + xp.asarray(np.arange(0, nb, self.bps, dtype=np.int64))[None, :]
        return xp.cast(xp.word(buf, byte, self.bps), xp.int64).reshape(-1, n, self.C)

    def locate(self, g: np.ndarray, loc: np.ndarray):
        """Header parsing for many (node, location) pairs (vectorized numpy).

        Returns:
            sel (S,) pairs that have a block; is_raw (S,); pay (S,) payload byte offsets;
            modes (S, P) uint8; mins (S, P) int64; pstart (S, P) byte offset of each plane.
        """
        buf = self.buf
        o0, o1 = self.index[loc], self.index[loc + 1]
        if self.verify is not None:
            u = np.unique(loc)
            self.verify(self.index[u], self.index[u + 1])
        nonempty = o1 > o0
        ne = np.flatnonzero(nonempty)                # every run read: its bitmap is checked whole
        if ne.size:
            if (o1[ne] - o0[ne] < self.nbm).any():
                raise FormatError("rlfc block run is shorter than its bitmap (corrupt file)")
            if self._high and self.nbm and (buf[o0[ne] + self.nbm - 1] & self._high).any():
                raise FormatError("rlfc block run's bitmap names a node the tree does not have (corrupt file)")
        byte = buf[np.where(nonempty, o0 + (g >> 3), 0)]
        present = nonempty & (((byte >> (g & 7).astype(np.uint8)) & 1) == 1)
        sel = np.flatnonzero(present)
        S = sel.size
        if S == 0:
            z = np.zeros((0, self.P), np.int64)
            return sel, np.zeros(0, bool), np.zeros(0, np.int64), z.astype(np.uint8), z, z
        s0, s1, sg = o0[sel], o1[sel], g[sel]
        bm = buf[s0[:, None] + np.arange(self.nbm)]                     # (S, nbm)
        pc = _POPCOUNT[bm]
        total = pc.sum(axis=1)
        pc[np.arange(self.nbm)[None, :] >= (sg >> 3)[:, None]] = 0
        part = _POPCOUNT[bm[np.arange(S), sg >> 3] & ((1 << (sg & 7)) - 1).astype(np.uint8)]
        rank = pc.sum(axis=1) + part
        heads_end = s0 + self.nbm + total * self.hs                     # payloads start here
        if (heads_end > s1).any():
            raise FormatError("rlfc block run is shorter than its block headers (corrupt file)")
        hdr = buf[(s0 + self.nbm + rank * self.hs)[:, None] + np.arange(self.hs)]   # (S, hs)
        pay = s0 + _from_le(hdr[:, :self.off_bytes], False)
        modes = hdr[:, self.off_bytes:self.off_bytes + self.P]
        mins = _from_le(hdr[:, self.off_bytes + self.P:].reshape(-1, self.min_bytes), True).reshape(-1, self.P)
        is_raw = modes[:, 0] == MODE_RAW
        check_blocks(modes, mins, self.q16)
        psize = self.table[modes]
        psize[is_raw] = 0
        pstart = pay[:, None] + (np.cumsum(psize, axis=1) - psize)
        end = np.where(is_raw, pay + self.B * self.B * self.C * self.bps, (pstart + psize).max(axis=1))
        if (pay < heads_end).any() or (end > s1).any():
            raise FormatError("rlfc block payload lies outside its run (corrupt file)")
        return sel, is_raw, pay, modes, mins, pstart

    def fetch_one(self, loc: int, nodes: list[int]):
        """One location, a few nodes (a single-block request): header parsing in Python ints.

        Returns:
            list, per node in ``nodes``: None (no block), ("raw", px (n, C)) or ("q", q (n, P)).
        """
        a, b = int(self.index[loc]), int(self.index[loc + 1])
        out = [None] * len(nodes)
        if a == b:
            return out
        if self.verify_span is not None:
            self.verify_span(a, b)
        buf = self.buf
        n, P = self.B * self.B, self.P
        if b - a < self.nbm:
            raise FormatError("rlfc block run is shorter than its bitmap (corrupt file)")
        bitmap = int.from_bytes(buf[a:a + self.nbm].tobytes(), "little")
        if self.n_nodes is not None and bitmap >> self.n_nodes:
            raise FormatError("rlfc block run's bitmap names a node the tree does not have (corrupt file)")
        heads_end = a + self.nbm + bin(bitmap).count("1") * self.hs
        if heads_end > b:
            raise FormatError("rlfc block run is shorter than its block headers (corrupt file)")
        jobs = {}
        for i, g in enumerate(nodes):
            if not (bitmap >> g) & 1:
                continue
            h = a + self.nbm + bin(bitmap & ((1 << g) - 1)).count("1") * self.hs
            hb = buf[h:h + self.hs].tobytes()
            pos = a + int.from_bytes(hb[:self.off_bytes], "little")
            modes = hb[self.off_bytes:self.off_bytes + P]
            mb = self.off_bytes + P
            mins = [int.from_bytes(hb[mb + c * self.min_bytes:mb + (c + 1) * self.min_bytes], "little", signed=True)
                    for c in range(P)]
            check_modes(np.frombuffer(modes, np.uint8)[None])
            if self._q16s is not None and modes[0] != MODE_RAW and any(     # check_blocks' rule, Python ints
                    (max(abs(mn), abs(mn + _VMAX_LIST[m])) * q + 8) >> 4 > MAX_RESIDUAL
                    for m, mn, q in zip(modes, mins, self._q16s)):
                raise FormatError(f"rlfc block header allows residuals beyond ±{MAX_RESIDUAL} (corrupt file)")
            if pos < heads_end:
                raise FormatError("rlfc block payload lies outside its run (corrupt file)")
            if modes[0] == MODE_RAW:
                nbytes = n * self.C * self.bps
                if pos + nbytes > b:
                    raise FormatError("rlfc block payload lies outside its run (corrupt file)")
                dt = "<u2" if self.bps == 2 else np.uint8
                out[i] = ("raw", np.frombuffer(buf[pos:pos + nbytes].tobytes(), dtype=dt).astype(np.int64).reshape(n, self.C))
                continue
            q = np.empty((n, P), dtype=np.int32)
            out[i] = ("q", q)
            for c in range(P):
                m = modes[c]
                if m == MODE_CONST:
                    q[:, c] = mins[c]
                else:
                    jobs.setdefault(m, []).append((pos, i, c, mins[c]))
                pos += int(self.table[m])
            if pos > b:
                raise FormatError("rlfc block payload lies outside its run (corrupt file)")
        for m, js in jobs.items():                       # one vectorized decode per distinct mode
            starts = np.fromiter((j[0] for j in js), dtype=np.int64, count=len(js))
            if m < MODE_CONST:
                vals = bise.decode_words(NUMPY, buf, starts, RANGE_VALUES[m], n)
            elif MODE_PLAIN < m < MODE_PLAIN + 32:
                vals = plain_values(NUMPY, buf, starts, m - MODE_PLAIN, n)
            else:
                raise ChecksumError(f"rlfc block has invalid plane mode {m} (corrupt file)")
            for (_, i, c, mn), v in zip(js, vals):
                out[i][1][:, c] = v.astype(np.int32) + mn
        return out
