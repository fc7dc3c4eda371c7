"""A slow reference decoder of .lfc files, written from docs/FORMAT.md alone.

It is the fuzzer's oracle (``tools/fuzz.py``): every mutant the library's decoders accept is
decoded again here and must give the same pixels. Nothing here imports the library's decoders,
bit readers or transforms; it reads the container itself, parses every field it needs from the
text of FORMAT.md, and loops over blocks and values in plain Python. It is deliberately slow
(seconds for a 4×4-view thumbnail file) and is never used to decode for users.

Covered: the container; RLFC profiles ``bise`` and ``dcp`` (every level); the LFN codec (every
level, float64 — compare within one grey level). Profile ``tx`` is checked against the second
reader written from FORMAT.md, the browser viewer's JavaScript decoder
(``tools/web_decode.mjs``), which reads tx layout versions 2-6 (tx.maps versions 2 and 3).

Usage::

    from tools.refdecode import ref_decode
    views = ref_decode(blob, level)     # (rows, cols, H, W, C) array, the file's dtype

Errors are :class:`RefError` (the reference refuses the file); their text says which rule.
"""
from __future__ import annotations

import json
import struct
import zlib

import numpy as np

MAGIC = b"\x89LFC\r\n\x1a\n"


class RefError(Exception):
    """The reference decoder refuses the file (the message names the rule of FORMAT.md)."""


def need(cond, msg: str):
    if not cond:
        raise RefError(msg)


# -- container ---------------------------------------------------------------------------
def read_container(blob: bytes) -> dict[str, bytes]:
    """Section name → bytes, after checking the header, the table, tiling and every chunk CRC."""
    need(len(blob) >= 32 and blob[:8] == MAGIC, "magic")
    major, minor, ns, nc, hcrc = struct.unpack_from("<HHIII", blob, 8)
    need(major == 1 and 1 <= ns <= 4096, "version / n_sections")
    need(blob[24:32] == bytes(8), "reserved header bytes")
    crc_at = 32 + 48 * ns
    data_at = crc_at + 4 * nc
    need(data_at <= len(blob), "table and CRC array fit")
    need(zlib.crc32(blob[:20] + blob[32:data_at]) == hcrc, "header CRC")
    crcs = struct.unpack_from(f"<{nc}I", blob, crc_at)
    out, pos = {}, data_at
    for i in range(ns):
        e = blob[32 + 48 * i: 80 + 48 * i]
        name = e[:16].rstrip(b"\0").decode("ascii")
        off, ln, cs, first, flags, res = struct.unpack_from("<QQIIII", e, 16)
        need(off == pos and cs > 0 and flags == 0 and res == 0, f"section {name} table entry")
        need(name not in out, "unique names")
        nch = -(-ln // cs)
        need(first + nch <= nc, "CRC slots")
        sec = blob[off:off + ln]
        need(len(sec) == ln, "truncated")
        for k in range(nch):
            need(zlib.crc32(sec[k * cs:(k + 1) * cs]) == crcs[first + k], f"{name} chunk {k} CRC")
        out[name] = sec
        pos = off + ln
    need(pos == len(blob) and "meta" in out, "sections tile the file; meta present")
    return out


# -- shared pieces ---------------------------------------------------------------------------
def pint(v, lo=0, hi=2 ** 31):
    need(type(v) is int and lo <= v <= hi, f"integer {v!r} in [{lo}, {hi}]")
    return v


def to_planes(img: np.ndarray, C: int) -> list[np.ndarray]:
    """Pixels (H, W, C) → planes as Python-int numpy object arrays: YCoCg-R for RGB, alpha last."""
    x = img.astype(np.int64)
    if C in (1, 2):
        return [x[..., c] for c in range(C)]
    r, g, b = x[..., 0], x[..., 1], x[..., 2]
    co = r - b
    t = b + (co >> 1)
    cg = g - t
    y = t + (cg >> 1)
    return [y, co, cg] + ([x[..., 3]] if C == 4 else [])


def from_planes(planes: list[np.ndarray], C: int, depth: int) -> np.ndarray:
    if C in (1, 2):
        px = list(planes)
    else:
        y, co, cg = planes[:3]
        t = y - (cg >> 1)
        g = cg + t
        b = t - (co >> 1)
        r = b + co
        px = [r, g, b] + list(planes[3:])
    return np.clip(np.stack(px, -1), 0, 2 ** depth - 1)


def decode_image(codec: str, data: bytes) -> np.ndarray:
    import imagecodecs
    try:
        img = imagecodecs.jpeg2k_decode(data) if codec == "j2k" else imagecodecs.jpegxl_decode(data)
    except Exception as e:  # noqa: BLE001 - any codec failure is a refusal
        raise RefError(f"key image: {e}") from None
    return img if img.ndim == 3 else img[..., None]


# -- BISE (ASTC integer sequence encoding) ---------------------------------------------------
RANGES = [2, 3, 4, 5, 6, 8, 10, 12, 16, 20, 24, 32, 40, 48, 64, 80, 96, 128, 160, 192, 256]


def ise_shape(rng: int) -> tuple[int, int]:
    """(kind, n bits): kind 0 = plain bits, 3 = trits, 5 = quints; rng = kind·2^n or 2^n."""
    for kind in (3, 5):
        if rng % kind == 0:
            return kind, (rng // kind).bit_length() - 1
    return 0, rng.bit_length() - 1


def ise_bits(rng: int, count: int) -> int:
    kind, n = ise_shape(rng)
    if kind == 3:
        return count * n + -(-8 * count // 5)
    if kind == 5:
        return count * n + -(-7 * count // 3)
    return count * n


def bit(v, i):
    return (v >> i) & 1


def trits(T: int) -> list[int]:
    """ASTC's decoding of 8 bits into 5 trits."""
    if (T >> 2) & 7 == 7:
        C = (((T >> 5) & 7) << 2) | (T & 3)
        t4 = t3 = 2
    else:
        C = T & 31
        if (T >> 5) & 3 == 3:
            t4, t3 = 2, bit(T, 7)
        else:
            t4, t3 = bit(T, 7), (T >> 5) & 3
    if C & 3 == 3:
        t2, t1, t0 = 2, bit(C, 4), (bit(C, 3) << 1) | (bit(C, 2) & (1 - bit(C, 3)))
    elif (C >> 2) & 3 == 3:
        t2, t1, t0 = 2, 2, C & 3
    else:
        t2, t1, t0 = bit(C, 4), (C >> 2) & 3, (bit(C, 1) << 1) | (bit(C, 0) & (1 - bit(C, 1)))
    return [t0, t1, t2, t3, t4]


def quints(Q: int) -> list[int]:
    """ASTC's decoding of 7 bits into 3 quints."""
    if (Q >> 1) & 3 == 3 and (Q >> 5) & 3 == 0:
        q2 = (bit(Q, 0) << 2) | ((bit(Q, 4) & (1 - bit(Q, 0))) << 1) | (bit(Q, 3) & (1 - bit(Q, 0)))
        return [4, 4, q2]
    if (Q >> 1) & 3 == 3:
        q2 = 4
        C = (((Q >> 3) & 3) << 3) | ((~(Q >> 5) & 3) << 1) | (Q & 1)
    else:
        q2 = (Q >> 5) & 3
        C = Q & 31
    if C & 7 == 5:
        q1, q0 = 4, (C >> 3) & 3
    else:
        q1, q0 = (C >> 3) & 3, C & 7
    return [q0, q1, q2]


class Bits:
    """LSB-first bit reader over the first ``nbits`` bits of bytes; reading past them gives
    zeros (ASTC's rule for the last, partial group; padding bits are ignored)."""

    def __init__(self, data: bytes, nbits: int | None = None):
        self.v = int.from_bytes(data, "little")
        if nbits is not None:
            self.v &= (1 << nbits) - 1
        self.pos = 0

    def take(self, n: int) -> int:
        r = (self.v >> self.pos) & ((1 << n) - 1)
        self.pos += n
        return r


def bise_decode(data: bytes, rng: int, count: int) -> list[int]:
    kind, n = ise_shape(rng)
    br, out = Bits(data, ise_bits(rng, count)), []
    if kind == 0:
        return [br.take(n) for _ in range(count)]
    layout = [2, 2, 1, 2, 1] if kind == 3 else [3, 2, 2]
    while len(out) < count:
        ms, packed, shift = [], 0, 0
        for w in layout:
            ms.append(br.take(n))
            packed |= br.take(w) << shift
            shift += w
        digits = trits(packed) if kind == 3 else quints(packed)
        out += [d << n | m for d, m in zip(digits, ms)]
    return out[:count]


# -- RLFC bise / dcp -------------------------------------------------------------------------
class Rlfc:
    def __init__(self, meta: dict, secs: dict[str, bytes]):
        c, s = meta["config"], meta["scene"]
        self.profile = c.get("profile", "bise")
        need(self.profile in ("bise", "dcp"), f"profile {self.profile!r} not covered here")
        self.rows, self.cols = pint(s["rows"], 1, 65536), pint(s["cols"], 1, 65536)
        self.B = pint(c["block_size"], 1, 256)
        self.P = self.C = pint(c["planes"], 1, 4)
        need(c["channels"] == self.C, "planes = channels")
        need(c["dtype"] in ("uint8", "uint16"), "dtype")
        self.dtype = np.dtype(c["dtype"])
        self.depth = 8 * self.dtype.itemsize
        self.H, self.W = pint(c["height"], 1), pint(c["width"], 1)
        self.Hp, self.Wp = (pint(v, 1) for v in c["padded"])
        self.nby, self.nbx = (pint(v, 1) for v in c["blocks"])
        need(self.Hp == self.nby * self.B >= self.H and self.Wp == self.nbx * self.B >= self.W, "padded size")
        need(self.Hp * self.Wp <= 2 ** 26, "pixels per view cap")
        self.q16 = [pint(q, 1, 2 ** 62) for q in c["q16"]]
        need(len(self.q16) == self.P, "q16 per plane")
        sizes, parents = c["tree"]["sizes"], c["tree"]["parents"]
        self.Ht = len(parents)
        need(len(sizes) == self.Ht + 1 and sizes[0] == self.rows * self.cols and 1 <= self.Ht <= 16, "tree")
        for l in range(self.Ht):
            need(len(parents[l]) == sizes[l] and all(pint(p, 0, sizes[l + 1] - 1) == p for p in parents[l]),
                 "tree parents")
        self.sizes, self.parents = [pint(x, 1, 65536) for x in sizes], parents
        self.level_offset = [pint(x, 0) for x in c["level_offset"]]
        self.nres = pint(c["n_res_nodes"], 1)
        need(len(self.level_offset) == self.Ht and self.nres == sum(self.sizes[:self.Ht]), "level_offset / nodes")
        lay = c["layout"]
        self.ob, self.mb, self.nbm = pint(lay["off_bytes"], 1, 8), pint(lay["min_bytes"], 1, 8), pint(lay["bitmap_bytes"])
        need(self.nbm == -(-self.nres // 8), "bitmap bytes")
        self.hs = self.ob + self.P + self.P * self.mb
        top = c["top"]
        need(len(top) == self.sizes[self.Ht], "one top image per top node")
        self.top = []
        for t in top:
            o, ln = pint(t["offset"], 0, 2 ** 62), pint(t["length"], 0, 2 ** 62)
            need(t["codec"] in ("j2k", "jxl") and o + ln <= len(secs["rlfc.top"]), "top entry")
            img = decode_image(t["codec"], secs["rlfc.top"][o:o + ln])
            need(img.shape == (self.Hp, self.Wp, self.C) and img.dtype == self.dtype, "top image shape/dtype")
            self.top.append(to_planes(img, self.C))
        nloc = self.nby * self.nbx
        if c.get("index_coding") == "zlib-runlen":
            lens = np.frombuffer(self.inflate(secs["rlfc.index"], 4 * nloc), "<u4")
            need(lens.size == nloc, "index run lengths")
            self.index = [0] + list(np.cumsum(lens.astype(object)))
        else:
            need("index_coding" not in c, "index coding")
            raw = secs["rlfc.index"]
            need(len(raw) == 4 * (nloc + 1), "index size")
            self.index = list(struct.unpack(f"<{nloc + 1}I", raw))
        self.blocks = secs["rlfc.blocks"]
        need(all(a <= b for a, b in zip(self.index, self.index[1:])) and self.index[-1] <= len(self.blocks),
             "index offsets")
        if self.profile == "dcp":
            need(self.Ht == 1, "dcp tree height 1")
            d = c["dcp"]
            self.F = pint(d["frac_bits"], 0, 4)
            need(d["disp_coding"] == "zlib-delta" and d["disp_dtype"] in ("<i1", "<i2"), "disp coding")
            dt = np.dtype(d["disp_dtype"])
            n_top = self.sizes[1]
            diffs = np.frombuffer(self.inflate(secs["rlfc.disp"], dt.itemsize * n_top * nloc), dt)
            need(diffs.size == n_top * nloc, "disp size")
            span = 1 << (8 * dt.itemsize)
            self.disp = []
            for k in range(n_top):
                row, acc = [], 0
                for v in diffs[k * nloc:(k + 1) * nloc].tolist():
                    acc = (acc + v + span // 2) % span - span // 2
                    row.append(acc)
                self.disp.append(row)
            self.offsets = d["offsets"]
            need(len(self.offsets) == self.rows * self.cols, "offsets per view")
            for v, (oy, ox) in enumerate(self.offsets):
                pint(oy, -2 ** 31, 2 ** 31), pint(ox, -2 ** 31, 2 ** 31)
                r, cc = divmod(v, self.cols)
                need(0 <= r - oy < self.rows and 0 <= cc - ox < self.cols, "dcp offset inside the grid")
        self.levels = self.Ht

    @staticmethod
    def inflate(data: bytes, cap: int) -> bytes:
        z = zlib.decompressobj()
        try:
            out = z.decompress(data, cap + 1)
        except zlib.error as e:
            raise RefError(f"zlib: {e}") from None
        need(len(out) <= cap and z.eof and not z.unused_data, "zlib stream length")
        return out

    # one run → {node: ("raw", planes) | ("res", planes of r)}
    def run(self, loc: int) -> dict:
        a, b = self.index[loc], self.index[loc + 1]
        run = self.blocks[a:b]
        if not run:
            return {}
        need(len(run) >= self.nbm, "run shorter than its bitmap")
        bm = int.from_bytes(run[:self.nbm], "little")
        nodes = [g for g in range(8 * self.nbm) if bm >> g & 1]
        need(all(g < self.nres for g in nodes), "bitmap bit beyond the nodes")
        hend = self.nbm + len(nodes) * self.hs
        need(len(run) >= hend, "run shorter than its headers")
        BB, out = self.B * self.B, {}
        for i, g in enumerate(nodes):
            h = run[self.nbm + i * self.hs: self.nbm + (i + 1) * self.hs]
            off = int.from_bytes(h[:self.ob], "little")
            modes = list(h[self.ob:self.ob + self.P])
            mins = [int.from_bytes(h[self.ob + self.P + p * self.mb: self.ob + self.P + (p + 1) * self.mb], "little",
                                   signed=True) for p in range(self.P)]
            need(off >= hend, "payload starts inside the headers")
            if modes[0] == 255:
                need(all(m == 21 for m in modes[1:]), "raw block's other planes are 21")
                nb = BB * self.C * self.dtype.itemsize
                need(off + nb <= len(run), "payload ends past its run")
                px = np.frombuffer(run[off:off + nb], self.dtype.newbyteorder("<")).reshape(self.B, self.B, self.C)
                out[g] = ("raw", to_planes(px, self.C))
                continue
            planes, pos = [], off
            for p, m in enumerate(modes):
                if m == 21:
                    vals = [0] * BB
                elif m <= 20:
                    nbytes = -(-ise_bits(RANGES[m], BB) // 8)
                    need(pos + nbytes <= len(run), "payload ends past its run")
                    vals = bise_decode(run[pos:pos + nbytes], RANGES[m], BB)
                    pos += nbytes
                elif 33 <= m <= 63:
                    k = m - 32
                    nbytes = -(-k * BB // 8)
                    need(pos + nbytes <= len(run), "payload ends past its run")
                    br = Bits(run[pos:pos + nbytes])
                    vals = [br.take(k) for _ in range(BB)]
                    pos += nbytes
                else:
                    raise RefError(f"undefined plane mode {m}")
                q16 = self.q16[p]
                res = []
                for v in vals:
                    q = v + mins[p]
                    mag = (abs(q) * q16 + 8) >> 4
                    res.append(-mag if q < 0 else mag)
                planes.append(np.array(res, dtype=object).reshape(self.B, self.B))
            out[g] = ("res", planes)
        return out

    def decode(self, level: int) -> np.ndarray:
        need(0 <= level <= self.levels, "level")
        B, N0 = self.B, self.rows * self.cols
        out = np.zeros((N0, self.Hp, self.Wp, self.C), np.int64)
        for by in range(self.nby):
            for bx in range(self.nbx):
                loc = by * self.nbx + bx
                stored = self.run(loc)
                ys, xs = slice(by * B, by * B + B), slice(bx * B, bx * B + B)
                blocks = self.bise_blocks(stored, ys, xs, level) if self.profile == "bise" else \
                    self.dcp_blocks(stored, by, bx, loc, level)
                for v in range(N0):
                    out[v, ys, xs] = from_planes(blocks[v], self.C, self.depth)
        H, W = self.H, self.W
        return out[:, :H, :W].reshape(self.rows, self.cols, H, W, self.C).astype(self.dtype)

    def bise_blocks(self, stored, ys, xs, level):
        """Planes of every view's block at one location, level ``level``."""
        dec = [[pl[ys, xs].astype(object) for pl in t] for t in self.top]          # level Ht
        for l in range(self.Ht - 1, level - 1, -1):
            new = []
            for n in range(self.sizes[l]):
                g = self.level_offset[l] + n
                got = stored.get(g)
                if got and got[0] == "raw":
                    new.append([p.astype(object) for p in got[1]])
                else:
                    parent = dec[self.parents[l][n]]
                    new.append([parent[p] + (got[1][p] if got else 0) for p in range(self.P)])
            dec = new
        views = []
        for v in range(self.rows * self.cols):
            n = v
            for l in range(level):
                n = self.parents[l][n]
            views.append([p.astype(np.int64) for p in dec[n]])
        return views

    def dcp_blocks(self, stored, by, bx, loc, level):
        B, F = self.B, self.F
        s = 1 << F
        views = []
        for v in range(self.rows * self.cols):
            k = self.parents[0][v]
            d = self.disp[k][loc]
            oy, ox = self.offsets[v]
            top = self.top[k]
            planes = []
            for p in range(self.P):
                pred = np.zeros((B, B), dtype=object)
                for y in range(B):
                    for x in range(B):
                        Y = (by * B + y) * s + d * oy
                        X = (bx * B + x) * s + d * ox
                        y0, fy, x0, fx = Y >> F, Y & (s - 1), X >> F, X & (s - 1)

                        def at(yy, xx):
                            return int(top[p][min(max(yy, 0), self.Hp - 1), min(max(xx, 0), self.Wp - 1)])
                        a, b_, c_, e = at(y0, x0), at(y0, x0 + 1), at(y0 + 1, x0), at(y0 + 1, x0 + 1)
                        pred[y, x] = ((a * (s - fx) + b_ * fx) * (s - fy) + (c_ * (s - fx) + e * fx) * fy
                                      + s * s // 2) >> (2 * F)
                planes.append(pred)
            got = stored.get(v)                 # dcp: level 0 nodes are the views, ids 0..N0-1
            if level == 0 and got:
                planes = [p.astype(object) for p in got[1]] if got[0] == "raw" else \
                    [planes[p] + got[1][p] for p in range(self.P)]
            views.append([p.astype(np.int64) for p in planes])
        return views


# -- entry -----------------------------------------------------------------------------------
def ref_levels(blob: bytes) -> int:
    """The number of levels above full quality that :func:`ref_decode` accepts."""
    return _open(blob).levels


def _open(blob: bytes):
    secs = read_container(blob)
    try:
        meta = json.loads(secs["meta"].decode("utf-8"), parse_constant=lambda c: (_ for _ in ()).throw(
            RefError(f"non-JSON constant {c}")))
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise RefError(f"meta: {e}") from None
    try:
        if meta.get("codec") == "rlfc":
            need(meta.get("codec_version") == 1, "codec version")
            return Rlfc(meta, secs)
        if meta.get("codec") == "lfn":
            from tools.reflfn import RefLfn
            return RefLfn(meta, secs)
    except (KeyError, TypeError, ValueError, IndexError, AttributeError, OverflowError) as e:
        raise RefError(f"metadata: {type(e).__name__}: {e}") from None
    raise RefError(f"codec {meta.get('codec')!r} not covered here")


def ref_decode(blob: bytes, level: int = 0) -> np.ndarray:
    """Every view of the file at ``level``: (rows, cols, H, W, C) in the file's dtype
    (LFN: uint8 RGBA of the captured cameras). Raises RefError when the reference refuses."""
    dec = _open(blob)
    try:
        return dec.decode(level)
    except (KeyError, TypeError, ValueError, IndexError, OverflowError) as e:
        raise RefError(f"{type(e).__name__}: {e}") from None


def covers(blob: bytes) -> bool:
    """Whether this module (not the JavaScript reader) is the reference for this file."""
    try:
        meta = json.loads(read_container(blob)["meta"])
        return meta.get("codec") == "lfn" or (meta.get("codec") == "rlfc"
                                              and meta["config"].get("profile", "bise") in ("bise", "dcp"))
    except Exception:  # noqa: BLE001
        return False


__all__ = ["RefError", "ref_decode", "ref_levels", "covers", "read_container"]
