"""Decoder of the BISE-family profiles (``bise``, ``dcp``): a key-view tree whose top images
are decoded once at open, and BISE-packed residual blocks read by random access.

One integer reconstruction serves every path (full light field, one view, one block, many
blocks, numpy and torch): decoded node = where(raw, raw pixels, prediction + dequantized
residuals of its ancestors' levels). How a level is predicted from the one above is the
profile's :class:`DecodeStrategy`.
"""
from __future__ import annotations

import numpy as np

from formats.errors import FormatError
from formats.parallel import LOCAL_THREADS
from formats.pixels import forward_int, to_planes
from formats.schema import Fields

from .blocks import PAD, BlockStore, unpack_index
from .kernels import decode_planes, dequantize
from .profiles.base import ProfileDecoder
from .residual import from_blocks, to_blocks
from .topcodec import decode_image
from .tree import Tree
from .xp import NUMPY, torch_backend


class DecodeStrategy:
    """How a BISE-family profile predicts from the level above (decoder side)."""

    def open(self, dec: "KeyTreeDecoder", cfg: Fields, container) -> None:
        """Read and validate the profile's side information."""

    def predict_blocks(self, st: dict, xp, views, by, bx):
        """(M, B·B, P) prediction of level-0 blocks from the top images, before residuals.
        ``st``: the decoder's arrays (numpy, or torch copies from :meth:`arrays`)."""
        raise NotImplementedError

    def predict_one(self, dec: "KeyTreeDecoder", v: int, by: int, bx: int) -> np.ndarray:
        """One block's prediction, (B·B, P) int32 (scalar fast path)."""
        return self.predict_blocks(dec.st, NUMPY, np.array([v]), np.array([by]), np.array([bx]))[0]

    def predict_nodes(self, dec: "KeyTreeDecoder", level: int, ids: np.ndarray, above: np.ndarray,
                      above_ids: np.ndarray) -> np.ndarray:
        """(n, Hp, Wp, P) prediction of level-``level`` nodes ``ids`` from the decoded nodes
        ``above_ids`` of the level above (planes ``above``)."""
        raise NotImplementedError

    def arrays(self, dec: "KeyTreeDecoder") -> dict:
        """The numpy arrays ``predict_blocks`` reads (copied to a device by the torch decoder)."""
        return {}


class KeyTreeDecoder(ProfileDecoder):
    """Planes decoder of a BISE-family file (see :class:`rlfc.profiles.base.ProfileDecoder`)."""

    def __init__(self, container, header, cfg: Fields, strategy: DecodeStrategy, limits=None):
        from formats.limits import DEFAULT

        limits = limits or DEFAULT
        c, name = container, container.name
        self.container, self.strategy, self.hdr = c, strategy, header
        self.block_size = B = header.block_size
        self.Hp, self.Wp = header.padded
        self.nby, self.nbx = header.blocks
        self.P, self.channels, self.dtype = header.planes, header.channels, header.dtype
        self.n_views = header.n_views
        self.q16 = np.asarray(cfg.int_list("q16", length=self.P, lo=16, hi=1 << 24), dtype=np.int64)
        tcfg = cfg.sub("tree")
        parents = tcfg.list("parents", max_len=limits.max_tree_height)
        sizes = tcfg.int_list("sizes", min_len=1, max_len=limits.max_tree_height + 1, lo=1, hi=limits.max_views)
        if len(sizes) != len(parents) + 1:
            raise FormatError(f"{name}: rlfc tree has {len(parents)} parent lists for {len(sizes)} levels")
        plist = [Fields({"p": p}, f"{name}: config.tree.parents").int_list("p", length=n, lo=0, hi=m - 1)
                 for p, n, m in zip(parents, sizes, sizes[1:])]
        self.tree = Tree(tuple(np.asarray(p, dtype=np.int64) for p in plist), tuple(sizes), ())
        H = self.tree.height
        self.levels = H
        if sizes[0] != self.n_views:
            raise FormatError(f"{name}: rlfc tree does not match the {header.rows}x{header.cols} grid")
        self.level_offset = cfg.int_list("level_offset", length=H, lo=0)
        if self.level_offset != [sum(sizes[lv + 1:H]) for lv in range(H)]:
            raise FormatError(f"{name}: rlfc metadata is inconsistent (level offsets)")
        n_res = cfg.int("n_res_nodes", 0, limits.max_views * (limits.max_tree_height + 1))
        lay = cfg.sub("layout")
        layout = {"off_bytes": lay.int("off_bytes", choices=(2, 4)), "min_bytes": lay.int("min_bytes", choices=(2, 4)),
                  "bitmap_bytes": lay.int("bitmap_bytes", 0)}
        if n_res != sum(sizes[:H]) or layout["bitmap_bytes"] != -(-n_res // 8):
            raise FormatError(f"{name}: rlfc metadata is inconsistent (node count/bitmap)")
        top_cfg = cfg.list("top", max_len=limits.max_views)
        if len(top_cfg) != sizes[-1]:
            raise FormatError(f"{name}: rlfc config lists {len(top_cfg)} top images for {sizes[-1]} top nodes")
        if len(top_cfg) * self.Hp * self.Wp > limits.max_open_pixels:
            raise FormatError(f"{name}: {len(top_cfg)} top images of {self.Hp}x{self.Wp} exceed the open-time "
                              f"limit of {limits.max_open_pixels} pixels")
        index_coding = cfg.str("index_coding", choices=("raw-u32", "zlib-runlen"), default="raw-u32")
        self.anc = self.tree.ancestors()                    # (H+1, N0)
        # top level: decoded once, kept
        top = c.read("rlfc.top")
        imgs = []
        for i, t in enumerate(top_cfg):
            tf = Fields(t, f"{name}: config.top[{i}]")
            a, n = tf.int("offset", 0), tf.int("length", 0)
            if a + n > len(top):
                raise FormatError(f"{name}: top-level image {i} lies outside section 'rlfc.top'")
            imgs.append(decode_image(tf.str("codec", choices=("j2k", "jxl")), bytes(top[a:a + n]),
                                     (self.Hp, self.Wp, self.channels), self.dtype, threads=LOCAL_THREADS))
        self.top = to_planes(np.stack(imgs))                 # (N_H, Hp, Wp, P) int32
        # the same pixels laid out per block, so a block request is one contiguous row gather
        self.top_blocks = np.ascontiguousarray(to_blocks(self.top, B)).reshape(
            len(imgs), self.nby, self.nbx, B * B, self.P)      # (N_H, nby, nbx, B·B, P)
        strategy.open(self, cfg, c)
        nloc = self.nby * self.nbx
        idx = c.read("rlfc.index")
        if index_coding == "zlib-runlen":
            index = unpack_index(bytes(idx), nloc, name)
        elif len(idx) != 4 * (nloc + 1):
            raise FormatError(f"{name}: section 'rlfc.index' has {len(idx)} bytes, expected {4 * (nloc + 1)}")
        else:
            index = np.frombuffer(idx, dtype="<u4").astype(np.int64)
        if index[0] != 0 or (np.diff(index) < 0).any():
            raise FormatError(f"{name}: section 'rlfc.index' is not a non-decreasing offset table")
        info = c.info("rlfc.blocks")
        if info.length != index[-1] + PAD:
            raise FormatError(f"{name}: section 'rlfc.blocks' has {info.length} bytes, index says {index[-1] + PAD}")
        self._remote = c.is_remote
        self._layout, self._index, self._n_res = layout, index, n_res
        if self._remote:
            self.store = None
        else:
            buf = c.array("rlfc.blocks", verify=False)
            self.store = BlockStore(index, buf, self.P, B, self.channels, self.dtype.itemsize, layout,
                                    lambda a, b: c.verify_ranges("rlfc.blocks", a, b),
                                    lambda a, b: c.verify_span("rlfc.blocks", a, b), n_nodes=n_res, q16=self.q16)
        self.st = {"top_blocks": self.top_blocks, "anc_top": self.anc[H], **strategy.arrays(self)}
        self.n_blocks = cfg.int("n_blocks", 0, default=0)

    # -- helpers ----------------------------------------------------------------------------
    def _store_for(self, locs: np.ndarray) -> tuple[BlockStore, np.ndarray]:
        """A block store covering ``locs``; for byte-range sources only their runs are fetched."""
        if not self._remote:
            return self.store, locs
        u, inv = np.unique(locs, return_inverse=True)
        c = self.container
        parts, idx = [], [0]
        for a, b in zip(self._index[u].tolist(), self._index[u + 1].tolist()):   # one range read per run
            parts.append(np.frombuffer(c.read("rlfc.blocks", a, b), dtype=np.uint8))
            idx.append(idx[-1] + (b - a))
        buf = np.concatenate(parts + [np.zeros(PAD, np.uint8)])
        # the fetched runs are stored back to back: run i is idx[i]..idx[i+1] of the local buffer
        st = BlockStore(np.asarray(idx, dtype=np.int64), buf, self.P, self.block_size, self.channels,
                        self.dtype.itemsize, self._layout, n_nodes=self._n_res, q16=self.q16)
        return st, inv.reshape(-1)

    def _residual(self, store: BlockStore, g: np.ndarray, loc: np.ndarray, xp=NUMPY, buf=None):
        """Residuals of the (node, location) pairs that have blocks: sel (S,), raw (S,) bool,
        deq (S, B·B, P) int32, raw planes (S, B·B, P) int32 or None."""
        n = self.block_size ** 2
        sel, is_raw, pay, modes, mins, pstart = store.locate(g, loc)
        A = xp.asarray
        q = decode_planes(xp, store.buf if buf is None else buf, A(modes), A(mins), A(pstart), A(is_raw), n)
        deq = xp.cast(dequantize(xp, q, A(self.q16)[None, :, None]), xp.int32).swapaxes(1, 2)   # (S, n, P)
        rawp = None
        if is_raw.any():
            px = store.raw_samples(xp, store.buf if buf is None else buf, A(pay[is_raw]))   # (R, n, C) int64
            rawp = xp.cast(forward_int(px), xp.int32)
        return A(sel), A(is_raw), deq, rawp

    def _accumulate(self, xp, acc, M: int, nlev: int, sel, raw, deq, rawp):
        """Add each request's residuals top-down over ``nlev`` levels (raw blocks replace)."""
        lev_of = sel // M
        rpos = xp.cast(raw, xp.int64).cumsum(0) - 1 if rawp is not None else None   # index into rawp
        for i in range(nlev):                              # top-down over the tree height
            k = xp.flatnonzero(lev_of == i)
            req = sel[k] - i * M                            # each request at most once per level
            acc[req] += deq[k]
            if rawp is not None:
                r = raw[k]
                if bool(r.any()):
                    acc[req[r]] = rawp[rpos[k[r]]]
        return acc

    # -- ProfileDecoder ---------------------------------------------------------------------
    def blocks(self, views, by, bx, level):
        M = views.size
        acc = np.asarray(self.strategy.predict_blocks(self.st, NUMPY, views, by, bx), dtype=np.int32)  # (M, n, P), fresh
        H = self.levels
        if H > level and M:
            levs = list(range(H - 1, level - 1, -1))
            g = np.concatenate([self.level_offset[lv] + self.anc[lv][views] for lv in levs])
            store, lloc = self._store_for(by * self.nbx + bx)
            sel, raw, deq, rawp = self._residual(store, g, np.tile(lloc, len(levs)))
            self._accumulate(NUMPY, acc, M, len(levs), sel, raw, deq, rawp)
        return acc

    def block(self, v, by, bx, level):
        if self.store is None:
            return self.blocks(np.array([v]), np.array([by]), np.array([bx]), level)[0]
        # lean path: Python-int header parsing, one decode per distinct mode
        acc = self.strategy.predict_one(self, v, by, bx)
        levs = range(self.levels - 1, level - 1, -1)
        got = self.store.fetch_one(by * self.nbx + bx, [self.level_offset[lv] + int(self.anc[lv][v]) for lv in levs])
        for item in got:                                  # top-down
            if item is None:
                continue
            if item[0] == "raw":
                acc = to_planes(item[1].astype(self.dtype))
            else:
                acc = acc + dequantize(NUMPY, item[1].astype(np.int64), self.q16).astype(np.int32)
        return acc

    def _decode_nodes(self, level: int, nodes: np.ndarray | None = None) -> np.ndarray:
        """Decoded planes (N, Hp, Wp, P) of level-``level`` nodes, top-down, each node once."""
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
            out = np.empty((len(ids), self.Hp, self.Wp, self.P), dtype=np.int32)
            for a in range(0, len(ids), 8):
                chunk = ids[a:a + 8]
                g = np.repeat(self.level_offset[lv] + chunk, nloc)
                loc = np.tile(np.arange(nloc), len(chunk))
                store, lloc = self._store_for(loc)
                sel, raw, deq, rawp = self._residual(store, g, lloc)
                res = np.zeros((len(chunk) * nloc, B * B, self.P), dtype=np.int32)
                res[sel] = deq
                base = self.strategy.predict_nodes(self, lv, chunk, dec, ids_above)
                rec = base + from_blocks(res.reshape(len(chunk), self.nby, self.nbx, B, B, self.P))
                if raw.any():
                    rb = rec.reshape(len(chunk), self.nby, B, self.nbx, B, self.P).transpose(0, 1, 3, 2, 4, 5).copy()
                    flat = rb.reshape(-1, B * B, self.P)
                    flat[sel[raw]] = rawp
                    rec = from_blocks(flat.reshape(len(chunk), self.nby, self.nbx, B, B, self.P))
                out[a:a + 8] = rec
            dec, ids_above = out, ids
        return dec

    def views(self, views, level):
        if self.store is not None and views.size == self.n_views:
            self.container.verify_ranges("rlfc.blocks", np.array([0]), np.array([int(self._index[-1])]))
        nodes = np.unique(self.anc[level][views])
        whole = nodes.size == self.tree.sizes[level]
        dec = self._decode_nodes(level, None if whole else nodes)
        for lv in range(level - 1, -1, -1):       # a level-L approximation: carried down by the
            below = np.unique(self.anc[lv][views])  # predictions, without residuals below L
            dec = self.strategy.predict_nodes(self, lv, below, dec, nodes)
            nodes = below
        return dec[np.searchsorted(nodes, views)]

    def torch(self, device):
        return TorchKeyTree(self, device)

    def info(self) -> dict:
        return {"tree_levels": list(self.tree.sizes), "n_blocks": self.n_blocks}


class TorchKeyTree:
    """The same planes on a torch device: compressed blocks and top images copied once."""

    def __init__(self, dec: KeyTreeDecoder, device):
        import torch

        if dec.store is None:
            from formats.errors import ParameterError

            raise ParameterError("the torch decoder needs the whole file (not a byte-range source)")
        self.d = dec
        self.xp = xp = torch_backend(device)
        dec.container.verify_ranges("rlfc.blocks", np.array([0]), np.array([int(dec._index[-1])]))
        self.buf = torch.from_numpy(np.array(dec.store.buf, dtype=np.uint8)).to(xp.device)
        self.st = {k: xp.asarray(v) for k, v in dec.st.items()}

    def blocks(self, views, by, bx, level):
        """(M,) numpy requests (validated) → (M, B·B, P) int32 tensor."""
        d, xp = self.d, self.xp
        M = views.size
        A = xp.asarray
        acc = self.d.strategy.predict_blocks(self.st, xp, A(views), A(by), A(bx)).to(xp.int32).clone()
        H = d.levels
        if H > level and M:
            levs = list(range(H - 1, level - 1, -1))
            g = np.concatenate([d.level_offset[lv] + d.anc[lv][views] for lv in levs])
            sel, raw, deq, rawp = d._residual(d.store, g, np.tile(by * d.nbx + bx, len(levs)), xp, self.buf)
            d._accumulate(xp, acc, M, len(levs), sel, raw, deq, rawp)
        return acc
