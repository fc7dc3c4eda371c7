"""RLFC decoders: full light field, one view, one block (random access), many blocks
(batched), each at any progressive level. All share one integer reconstruction, so they agree
bit for bit: decoded node = where(raw, raw pixels, decoded parent + dequantized residual).

The file stays compressed (memory-mapped or behind a byte-range source); opening decodes only
the top-level key views (a few images) and reads the block-offset table.
"""
from __future__ import annotations

import numpy as np

from formats.container import ByteRangeSource
from formats.errors import FormatError, ParameterError
from formats.lfcfile import LfcFile, check_codec_version

from .blocks import PAD, BlockStore, unpack_index
from .color import from_planes, to_planes
from .disparity import planar, predict_blocks, predict_views, unpack_disparity
from .encoder import CODEC_ID, CODEC_VERSION
from .residual import dequantize, from_blocks, to_blocks
from .topcodec import decode_image
from .tree import Tree


class RlfcDecoder:
    """Decoder over an opened .lfc file.

    Attributes:
        rows, cols, height, width, channels, dtype: the light field's geometry.
        block_size: B. levels: tree height H (valid ``level`` arguments are 0..H).
    """

    def __init__(self, f: LfcFile):
        check_codec_version(f, CODEC_ID, CODEC_VERSION)
        self.file = f
        c = f.container
        try:
            cfg = f.meta["config"]
            scene = f.meta["scene"]
            self.rows, self.cols = int(scene["rows"]), int(scene["cols"])
            self.height, self.width = int(cfg["height"]), int(cfg["width"])
            self.channels, self.P = int(cfg["channels"]), int(cfg["planes"])
            self.dtype = np.dtype(cfg["dtype"])
            self.block_size = B = int(cfg["block_size"])
            self.Hp, self.Wp = map(int, cfg["padded"])
            self.nby, self.nbx = map(int, cfg["blocks"])
            self.q16 = np.asarray(cfg["q16"], dtype=np.int64)
            self.tree = Tree.from_config(cfg["tree"])
            self.level_offset = [int(x) for x in cfg["level_offset"]]
            layout = {k: int(cfg["layout"][k]) for k in ("off_bytes", "min_bytes", "bitmap_bytes")}
            top_cfg = list(cfg["top"])
            n_res = int(cfg["n_res_nodes"])
            self.profile = str(cfg.get("profile", "bise"))
            index_coding = str(cfg.get("index_coding", "raw-u32"))
            dcp = cfg.get("dcp") if self.profile == "dcp" else None
            self.frac_bits, disp_coding, disp_dtype = 0, "raw-i8", "<i1"
            if dcp is not None:
                self.offsets = np.asarray(dcp["offsets"], dtype=np.int64)
                self.frac_bits = int(dcp.get("frac_bits", 0))
                disp_coding = str(dcp.get("disp_coding", "raw-i8"))
                disp_dtype = str(dcp.get("disp_dtype", "<i1"))
        except (KeyError, TypeError, ValueError, ParameterError) as e:
            raise FormatError(f"{c.name}: rlfc metadata is incomplete or invalid ({type(e).__name__}: {e})") from None
        H = self.tree.height
        sizes = self.tree.sizes
        expect_off = [sum(sizes[lv + 1:H]) for lv in range(H)]
        problems = [
            (self.dtype not in (np.uint8, np.uint16), "dtype"),
            (B not in (2, 4, 8, 16, 32), "block size"),
            (not (1 <= self.channels <= 4 and self.P == self.channels), "channels/planes"),
            (not (0 < self.height <= self.Hp == self.nby * B and 0 < self.width <= self.Wp == self.nbx * B),
             "padded size/blocks"),
            (self.nby * self.nbx > 1 << 26, "block count"),
            (self.q16.shape != (self.P,) or (self.q16 < 16).any(), "q16"),
            (layout["off_bytes"] not in (2, 4) or layout["min_bytes"] not in (2, 4), "layout"),
            (n_res != sum(sizes[:H]) or layout["bitmap_bytes"] != -(-n_res // 8), "node count/bitmap"),
            (self.level_offset != expect_off, "level offsets"),
            (self.profile not in ("bise", "dcp"), f"profile {self.profile!r}"),
            (index_coding not in ("raw-u32", "zlib-runlen"), "index coding"),
            (self.profile == "dcp" and (dcp is None or H != 1 or
                                        self.offsets.shape != (self.rows * self.cols, 2) or
                                        not 0 <= self.frac_bits <= 4 or
                                        disp_coding not in ("raw-i8", "zlib-delta")), "dcp config"),
        ]
        bad = [what for cond, what in problems if cond]
        if bad:
            raise FormatError(f"{c.name}: rlfc metadata is inconsistent ({', '.join(bad)})")
        if self.tree.sizes[0] != self.rows * self.cols or len(top_cfg) != self.tree.sizes[-1]:
            raise FormatError(f"{c.name}: rlfc tree does not match the {self.rows}x{self.cols} grid")
        self.levels = self.tree.height
        self.anc = self.tree.ancestors()                    # (H+1, N0)
        # top level: decoded once, kept
        top = c.read("rlfc.top")
        imgs = []
        for i, t in enumerate(top_cfg):
            a, n = int(t["offset"]), int(t["length"])
            if a < 0 or a + n > len(top):
                raise FormatError(f"{c.name}: top-level image {i} lies outside section 'rlfc.top'")
            imgs.append(decode_image(t["codec"], bytes(top[a:a + n]), (self.Hp, self.Wp, self.channels), self.dtype))
        self.top = to_planes(np.stack(imgs))                  # (N_H, Hp, Wp, P) int32
        if self.profile == "dcp":
            raw_d = c.read("rlfc.disp")
            if disp_coding == "zlib-delta":
                self.disp = unpack_disparity(bytes(raw_d), disp_dtype, (len(imgs), self.nby * self.nbx), c.name)
            else:
                if len(raw_d) != len(imgs) * self.nby * self.nbx:
                    raise FormatError(f"{c.name}: section 'rlfc.disp' has {len(raw_d)} bytes, expected "
                                      f"{len(imgs) * self.nby * self.nbx}")
                self.disp = np.frombuffer(raw_d, dtype=np.int8).astype(np.int64).reshape(len(imgs), -1)
            self.key_of = self.tree.parents[0]
            self.top_planar = planar(self.top)                # (P, n_top·Hp·Wp): fast per-plane gathers
        # the same pixels laid out per block, so a block request is one contiguous row gather
        self.top_blocks = np.ascontiguousarray(to_blocks(self.top, B)).reshape(
            len(imgs), self.nby, self.nbx, B * B, self.P)      # (N_H, nby, nbx, B·B, P)
        idx = c.read("rlfc.index")
        if index_coding == "zlib-runlen":
            index = unpack_index(bytes(idx), self.nby * self.nbx, c.name)
        elif len(idx) != 4 * (self.nby * self.nbx + 1):
            raise FormatError(f"{c.name}: section 'rlfc.index' has {len(idx)} bytes, expected {4 * (self.nby * self.nbx + 1)}")
        else:
            index = np.frombuffer(idx, dtype="<u4").astype(np.int64)
        if index[0] != 0 or (np.diff(index) < 0).any():
            raise FormatError(f"{c.name}: section 'rlfc.index' is not a non-decreasing offset table")
        self._remote = isinstance(c._src, ByteRangeSource)
        info = c.info("rlfc.blocks")
        if self._remote:
            buf = np.zeros(0, np.uint8)
            verify = verify_span = None
        else:
            buf = c.array("rlfc.blocks", verify=False)
            verify = lambda a, b: c.verify_ranges("rlfc.blocks", a, b)  # noqa: E731
            verify_span = lambda a, b: c.verify_span("rlfc.blocks", a, b)  # noqa: E731
        if info.length != index[-1] + PAD:
            raise FormatError(f"{c.name}: section 'rlfc.blocks' has {info.length} bytes, index says {index[-1] + PAD}")
        self._layout = layout
        self._index = index
        self.store = None if self._remote else BlockStore(index, buf, self.P, B, self.channels, self.dtype.itemsize,
                                                           layout, verify, verify_span)

    # -- helpers ----------------------------------------------------------------------------
    def _store_for(self, locs: np.ndarray) -> tuple[BlockStore, np.ndarray]:
        """A block store covering ``locs``; for byte-range sources only their runs are fetched."""
        if not self._remote:
            return self.store, locs
        u, inv = np.unique(locs, return_inverse=True)
        c = self.file.container
        parts, idx = [], [0]
        for a, b in zip(self._index[u].tolist(), self._index[u + 1].tolist()):   # one range read per run
            parts.append(np.frombuffer(c.read("rlfc.blocks", a, b), dtype=np.uint8))
            idx.append(idx[-1] + (b - a))
        buf = np.concatenate(parts + [np.zeros(PAD, np.uint8)])
        # the fetched runs are stored back to back: run i is idx[i]..idx[i+1] of the local buffer
        st = BlockStore(np.asarray(idx, dtype=np.int64), buf, self.P, self.block_size, self.channels,
                        self.dtype.itemsize, self._layout)
        return st, inv.reshape(-1)

    def _requests(self, views, by, bx) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Batched (view, block row, block column) requests as int64 arrays, range-checked."""
        views = np.asarray(views, dtype=np.int64).reshape(-1)
        by = np.asarray(by, dtype=np.int64).reshape(-1)
        bx = np.asarray(bx, dtype=np.int64).reshape(-1)
        if views.size and (views.min() < 0 or views.max() >= self.rows * self.cols):
            raise ParameterError("view index out of range")
        if by.size and (by.min() < 0 or by.max() >= self.nby or bx.min() < 0 or bx.max() >= self.nbx):
            raise ParameterError(f"block index out of range (blocks are {self.nby} rows x {self.nbx} cols of "
                                 f"{self.block_size} px)")
        return views, by, bx

    def _pred_blocks(self, views: np.ndarray, by: np.ndarray, bx: np.ndarray) -> np.ndarray:
        """What each requested block starts from before residuals: (M, B·B, P) int32 planes —
        the top key view's block (bise) or the disparity-shifted key view (dcp)."""
        if self.profile == "dcp":
            return predict_blocks(self.top, self.key_of, self.offsets, self.disp, views, by, bx,
                                  self.block_size, self.nbx, self.frac_bits, self.top_planar)
        return self.top_blocks[self.anc[self.levels][views], by, bx]

    def _pred_one(self, v: int, by: int, bx: int) -> np.ndarray:
        """dcp prediction of one block with Python-int arithmetic and a slice of the key view
        (the same integers as :func:`predict_blocks`, without its per-request arrays): (B·B, P)."""
        B, F = self.block_size, self.frac_bits
        k = int(self.key_of[v])
        d = int(self.disp[k, by * self.nbx + bx])
        oy, ox = int(self.offsets[v, 0]), int(self.offsets[v, 1])
        Y, X = ((by * B) << F) + d * oy, ((bx * B) << F) + d * ox
        y0, x0, m = Y >> F, X >> F, (1 << F) - 1
        fy, fx = Y & m, X & m
        img = self.top[k]
        if 0 <= y0 and y0 + B < self.Hp and 0 <= x0 and x0 + B < self.Wp:
            win = img[y0:y0 + B + 1, x0:x0 + B + 1]
        else:   # clamp at the padded image's edges
            ys = np.clip(np.arange(y0, y0 + B + 1), 0, self.Hp - 1)
            xs = np.clip(np.arange(x0, x0 + B + 1), 0, self.Wp - 1)
            win = img[ys[:, None], xs[None, :]]
        if fy == 0 and fx == 0:
            return np.ascontiguousarray(win[:B, :B]).reshape(B * B, self.P)
        s = 1 << F
        h = win[:, :B] * (s - fx) + win[:, 1:] * fx                  # (B+1, B, P): horizontal pass
        return ((h[:B] * (s - fy) + h[1:] * fy + (1 << (2 * F - 1))) >> (2 * F)).reshape(B * B, self.P)

    def _check_level(self, level: int) -> int:
        if not 0 <= int(level) <= self.levels:
            raise ParameterError(f"level must be within 0..{self.levels} (0 = full quality, {self.levels} = top key views), got {level}")
        return int(level)

    def _view_index(self, row: int, col: int) -> int:
        if not (0 <= row < self.rows and 0 <= col < self.cols):
            raise ParameterError(f"view ({row},{col}) is outside the {self.rows}x{self.cols} grid")
        return row * self.cols + col

    def _residual(self, store: BlockStore, g: np.ndarray, loc: np.ndarray):
        """Compact residuals of the pairs that have blocks: (sel, raw, deq (S, n, P), raw planes)."""
        sel, raw, q, px = store.fetch(g, loc)
        deq = dequantize(q, self.q16)
        rawp = to_planes(px.astype(self.dtype)) if raw.any() else None
        return sel, raw, deq, rawp

    # -- decoders ---------------------------------------------------------------------------
    def decode_blocks(self, views: np.ndarray, by: np.ndarray, bx: np.ndarray, level: int = 0,
                      planes: bool = False) -> np.ndarray:
        """Batched random access: many (view, block) requests in one vectorized pass.

        Args:
            views: (M,) flat view indices (row·cols + col); by, bx: (M,) block indices.
            level: progressive level (0 = full quality .. H = top key views).
            planes: return int32 planes instead of pixels.

        Returns:
            (M, B, B, C) pixels (uint8/uint16; blocks past the image edge hold padding).
        """
        level = self._check_level(level)
        views, by, bx = self._requests(views, by, bx)
        M, B = views.size, self.block_size
        H = self.levels
        acc = self._pred_blocks(views, by, bx)                # (M, B·B, P)
        loc = by * self.nbx + bx
        if H > level:
            levs = list(range(H - 1, level - 1, -1))
            g = np.concatenate([self.level_offset[lv] + self.anc[lv][views] for lv in levs])
            store, lloc = self._store_for(loc)
            sel, raw, deq, rawp = self._residual(store, g, np.tile(lloc, len(levs)))
            lev_of = sel // M
            for i in range(len(levs)):       # top-down over the tree height
                k = np.flatnonzero(lev_of == i)    # each request at most once per level
                req = sel[k] - i * M
                acc[req] += deq[k]
                r = raw[k]
                if r.any():
                    acc[req[r]] = rawp[k[r]]
        acc = acc.reshape(M, B, B, self.P)
        return acc if planes else from_planes(acc, self.dtype)

    def decode_block(self, row: int, col: int, by: int, bx: int, level: int = 0) -> np.ndarray:
        """One block of one view: (b_h, b_w, C) pixels, cropped at the image edges.

        Block (by, bx) covers pixels [by·B, (by+1)·B) × [bx·B, (bx+1)·B).
        """
        v = self._view_index(row, col)
        if not (0 <= by < self.nby and 0 <= bx < self.nbx):
            raise ParameterError(f"block ({by},{bx}) is outside the {self.nby}x{self.nbx} block grid "
                                 f"({self.height}x{self.width} px, B={self.block_size})")
        level = self._check_level(level)
        B = self.block_size
        if self.store is None:
            out = self.decode_blocks(np.array([v]), np.array([by]), np.array([bx]), level)[0]
        else:   # lean path: Python-int header parsing, one decode per distinct mode
            acc = (self._pred_one(v, by, bx) if self.profile == "dcp"
                   else self._pred_blocks(np.array([v]), np.array([by]), np.array([bx]))[0])
            levs = range(self.levels - 1, level - 1, -1)
            got = self.store.fetch_one(by * self.nbx + bx, [self.level_offset[lv] + int(self.anc[lv][v]) for lv in levs])
            for item in got:                                  # top-down
                if item is None:
                    continue
                if item[0] == "raw":
                    acc = to_planes(item[1].astype(self.dtype))
                else:
                    acc = acc + dequantize(item[1], self.q16)
            out = from_planes(acc.reshape(B, B, self.P), self.dtype)
        return out[:min(B, self.height - by * B), :min(B, self.width - bx * B)]

    def _decode_nodes(self, level: int, nodes: np.ndarray | None = None) -> np.ndarray:
        """Decoded planes (N, Hp, Wp, P) of level-``level`` nodes, top-down, each node once."""
        dec = self.top
        nloc = self.nby * self.nbx
        B = self.block_size
        need = None
        if nodes is not None:    # only the ancestors of the wanted nodes at each level
            need = {level: np.unique(nodes)}
            for lv in range(level, self.levels):
                need[lv + 1] = np.unique(self.tree.parents[lv][need[lv]])
        ids_above = np.arange(self.tree.sizes[-1]) if need is None else need[self.levels]
        dec = self.top[ids_above]
        for lv in range(self.levels - 1, level - 1, -1):
            ids = np.arange(self.tree.sizes[lv]) if need is None else need[lv]
            par = self.tree.parents[lv][ids]
            ppos = np.searchsorted(ids_above, par)
            out = np.empty((len(ids), self.Hp, self.Wp, self.P), dtype=np.int32)
            for a in range(0, len(ids), 8):
                chunk = ids[a:a + 8]
                g = np.repeat(self.level_offset[lv] + chunk, nloc)
                loc = np.tile(np.arange(nloc), len(chunk))
                store, lloc = self._store_for(loc)
                sel, raw, deq, rawp = self._residual(store, g, lloc)
                res = np.zeros((len(chunk) * nloc, B * B, self.P), dtype=np.int32)
                res[sel] = deq
                base = (predict_views(self.top, self.key_of, self.offsets, self.disp, chunk, B, self.frac_bits,
                                      self.top_planar)
                        if self.profile == "dcp" else dec[ppos[a:a + 8]])
                rec = base + from_blocks(res.reshape(len(chunk), self.nby, self.nbx, B, B, self.P))
                if raw.any():
                    rb = rec.reshape(len(chunk), self.nby, B, self.nbx, B, self.P).transpose(0, 1, 3, 2, 4, 5).copy()
                    flat = rb.reshape(-1, B * B, self.P)
                    flat[sel[raw]] = rawp[raw]
                    rec = from_blocks(flat.reshape(len(chunk), self.nby, self.nbx, B, B, self.P))
                out[a:a + 8] = rec
            dec, ids_above = out, ids
        return dec

    def decode_views(self, views: list[int] | np.ndarray | None = None, level: int = 0, planes: bool = False) -> np.ndarray:
        """Decode whole views (flat indices; None = all) at a progressive level.

        Returns:
            (n, H, W, C) pixels (or int32 planes with ``planes=True``), cropped to the image.
        """
        level = self._check_level(level)
        views = np.arange(self.rows * self.cols) if views is None else np.asarray(views, dtype=np.int64).reshape(-1)
        if self.store is not None and views.size == self.rows * self.cols:
            self.file.container.verify_ranges("rlfc.blocks", np.array([0]), np.array([int(self._index[-1])]))
        if self.profile == "dcp" and level == self.levels:     # the prediction itself
            out = predict_views(self.top, self.key_of, self.offsets, self.disp, views, self.block_size,
                                self.frac_bits, self.top_planar)
            out = out[:, :self.height, :self.width]
            return out if planes else from_planes(out, self.dtype)
        nodes = self.anc[level][views]
        un = np.unique(nodes)
        dec = self._decode_nodes(level, None if un.size == self.tree.sizes[level] else un)
        pos = np.searchsorted(un, nodes) if un.size != self.tree.sizes[level] else nodes
        out = dec[pos][:, :self.height, :self.width]
        return out if planes else from_planes(out, self.dtype)

    def decode_view(self, row: int, col: int, level: int = 0) -> np.ndarray:
        """One view: (H, W, C) pixels."""
        return self.decode_views([self._view_index(row, col)], level)[0]

    def decode_all(self, level: int = 0) -> np.ndarray:
        """The whole light field: (rows, cols, H, W, C) pixels."""
        out = self.decode_views(None, level)
        return out.reshape(self.rows, self.cols, *out.shape[1:])
