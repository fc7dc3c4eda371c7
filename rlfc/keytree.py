"""The BISE-family encoder shared by the ``bise`` and ``dcp`` profiles: a key-view tree, a
top-down closed loop of sparse quantized residuals, BISE-packed blocks behind an offset table.

What differs between the profiles (how the key views are made, how a level is predicted from
the level above, the side sections) is a :class:`KeyStrategy`; this module holds no profile
branches.

Data path: views (R, C, H, W, Ch) → padded to multiples of B → key views per level (the
strategy) → top key views coded as images → top-down, per level: residual = YCoCg-R(node) −
prediction, thresholded and quantized; the decoded node is rebuilt from the quantized residual
(closed loop) → blocks packed per location.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from formats.errors import UnsupportedError
from formats.lightfield import LightField
from formats.pixels import plane_weights, to_planes

from . import blocks as blk
from .kernels import MODE_CONST  # noqa: F401  (re-exported for profile modules)
from .params import RlfcParams
from .residual import block_energy, from_blocks, quantize_dequantize, to_blocks
from .topcodec import decode_image, encode_image
from .tree import Tree


@dataclass
class LoopResult:
    """What the closed loop produced for one parameter set (before packing)."""

    tree: Tree
    dec0: np.ndarray            # (N0, Hp, Wp, P) int32 decoded view planes
    levels: list                # per level l (H-1..0): (g, loc, q, raw, raw_px)
    top: list                   # [(codec, bytes)] per top node
    top_dec: np.ndarray         # (N_H, Hp, Wp, P) int32


class KeyStrategy:
    """How a BISE-family profile makes key views and predicts each level from the one above."""

    profile = ""
    index_coding = "raw-u32"

    def build(self, enc: "KeyTreeEncoder", lf: LightField, views: np.ndarray, params: RlfcParams):
        """(tree, key images per level above the views: list of (N_l, Hp, Wp, C) arrays)."""
        raise NotImplementedError

    def prepare(self, enc: "KeyTreeEncoder", params: RlfcParams, side=None) -> None:
        """Estimate side information once the decoded top key views are known (``side``: a
        previous estimate to reuse)."""

    def predict(self, enc: "KeyTreeEncoder", level: int, nodes: np.ndarray, dec_above: np.ndarray) -> np.ndarray:
        """(n, Hp, Wp, P) int32 prediction of level-``level`` nodes from the decoded level above."""
        raise NotImplementedError

    def side(self, enc: "KeyTreeEncoder", params: RlfcParams) -> tuple[dict, list]:
        """(config entries, sections) of the side information."""
        return {}, []


def pad_to(x: np.ndarray, b: int) -> np.ndarray:
    """Pad (…, H, W, C) to multiples of b by repeating the last row/column."""
    h, w = x.shape[-3:-1]
    ph, pw = -h % b, -w % b
    if ph == 0 and pw == 0:
        return x
    pad = [(0, 0)] * (x.ndim - 3) + [(0, ph), (0, pw), (0, 0)]
    return np.pad(x, pad, mode="edge")


class KeyTreeEncoder:
    """Holds the parameter-independent work (key views, top images, side information) so rate
    control can re-run the closed loop for many quantizer settings cheaply."""

    def __init__(self, lf: LightField, params: RlfcParams, strategy: KeyStrategy, side=None):
        if lf.views.dtype not in (np.uint8, np.uint16):
            raise UnsupportedError(f"RLFC codes 8- or 16-bit integer views; this light field is {lf.views.dtype} "
                                   "(convert float/EXR views to 16-bit first)")
        self.lf, self.strategy = lf, strategy
        self.B = params.block_size
        r, c, h, w, ch = lf.views.shape
        self.dtype = lf.views.dtype
        self.bps = lf.views.dtype.itemsize
        self.P = ch
        self.views = pad_to(lf.views.reshape(r * c, h, w, ch), self.B)
        self.Hp, self.Wp = self.views.shape[1:3]
        self.nby, self.nbx = self.Hp // self.B, self.Wp // self.B
        self.tree, keys = strategy.build(self, lf, self.views, params)
        self.rkv = [self.views] + keys
        self.top = [encode_image(im, params.top_codec, params.top_psnr) for im in self.rkv[-1]]
        top_px = np.stack([decode_image(cd, data, im.shape, im.dtype) for (cd, data), im in zip(self.top, self.rkv[-1])])
        self.top_dec = to_planes(top_px)
        strategy.prepare(self, params, side)
        H = self.tree.height
        self.level_offset = {}        # BFS numbering of residual nodes: level H-1 first, level 0 last
        off = 0
        for lev in range(H - 1, -1, -1):
            self.level_offset[lev] = off
            off += self.tree.sizes[lev]
        self.n_res_nodes = off

    def closed_loop(self, params: RlfcParams, keep_blocks: bool = True) -> LoopResult:
        """Run the top-down closed loop for one set of threshold/quant/energy parameters."""
        B, P = self.B, self.P
        q16 = np.full(P, params.q16, dtype=np.int64)
        thr = np.full(P, float(params.threshold))
        if P in (2, 4):   # alpha is always lossless
            q16[-1], thr[-1] = 16, 0.0
        w = plane_weights(P)
        dec = self.top_dec
        levels = []
        for lev in range(self.tree.height - 1, -1, -1):
            n_l = self.tree.sizes[lev]
            nxt = np.empty((n_l, self.Hp, self.Wp, P), dtype=np.int32)
            for a in range(0, n_l, 16):   # chunks of nodes bound the memory of one level
                s = slice(a, min(a + 16, n_l))
                pred = self.strategy.predict(self, lev, np.arange(s.start, s.stop), dec)
                target = to_planes(self.rkv[lev][s])
                q, deq = quantize_dequantize(target - pred, q16, thr)
                qb = to_blocks(q, B)                                      # (n, nby, nbx, B, B, P)
                db = to_blocks(deq, B)
                keep = np.any(qb != 0, axis=(3, 4, 5))
                if params.energy > 0:
                    strong = block_energy(db, w) >= params.energy
                    if P in (2, 4):   # alpha is lossless: a block with any alpha residual stays
                        strong |= np.any(qb[..., -1] != 0, axis=(3, 4))
                    keep &= strong
                # raw escape: a block whose coded size is not clearly below its raw pixels is stored
                # raw (exact, and it frees its ancestors' blocks for pruning)
                kn, ky, kx = np.nonzero(keep)
                qk = qb[kn, ky, kx].reshape(len(kn), B * B, P).transpose(0, 2, 1)  # (K, P, n)
                modes = blk.plane_modes(qk.min(axis=2), qk.max(axis=2)) if len(kn) else np.zeros((0, P), np.uint8)
                coded = blk.mode_bytes_table(B * B)[modes].sum(axis=1)
                raw = coded * 8 >= 7 * B * B * self.lf.channels * self.bps
                tb = to_blocks(target, B)
                db_out = np.where(keep[..., None, None, None], db, 0)
                rec = pred + from_blocks(db_out)
                if raw.any():
                    rb = to_blocks(rec, B)
                    rb[kn[raw], ky[raw], kx[raw]] = tb[kn[raw], ky[raw], kx[raw]]
                    rec = from_blocks(rb)
                nxt[s] = rec
                if keep_blocks:
                    rawpx = to_blocks(self.rkv[lev][s], B)[kn[raw], ky[raw], kx[raw]].reshape(
                        int(raw.sum()), B * B * self.lf.channels)
                    raw_full = np.zeros((len(kn), B * B * self.lf.channels), dtype=np.int64)
                    raw_full[raw] = rawpx
                    g = self.level_offset[lev] + a + kn
                    loc = ky * self.nbx + kx
                    levels.append((g, loc, np.where(raw[:, None, None], 0, qk), raw, raw_full))
            dec = nxt
        return LoopResult(self.tree, dec, levels, self.top, self.top_dec)

    def prune(self, res: LoopResult) -> list:
        """Drop key-view blocks that no descendant uses.

        A node's block at a location is useless when every child there is independent of it:
        stored raw, or itself pruned (recursively). Pruning leaves every view's reconstruction
        unchanged; it matters on noise-like content, where children are stored raw.
        """
        if not res.levels:
            return res.levels
        nloc = self.nby * self.nbx
        g = np.concatenate([x[0] for x in res.levels])
        loc = np.concatenate([x[1] for x in res.levels])
        raw = np.concatenate([x[3] for x in res.levels])
        keep = np.ones(len(g), dtype=bool)
        indep_below = None
        for lev in range(0, self.tree.height):           # bottom-up
            lo = self.level_offset[lev]
            n_l = self.tree.sizes[lev]
            sel = (g >= lo) & (g < lo + n_l)
            indep = np.zeros((n_l, nloc), dtype=bool)
            indep[g[sel] - lo, loc[sel]] = raw[sel]
            if indep_below is not None:
                par = self.tree.parents[lev - 1]
                cnt = np.zeros((n_l, nloc), dtype=np.int32)
                order = np.argsort(par, kind="stable")
                starts = np.flatnonzero(np.r_[True, par[order][1:] != par[order][:-1]])
                cnt[np.unique(par)] = np.add.reduceat(indep_below[order].astype(np.int32), starts, axis=0)
                pruned = cnt == np.bincount(par, minlength=n_l)[:, None]
                keep[sel] = ~pruned[g[sel] - lo, loc[sel]]
                indep |= pruned
            indep_below = indep
        if keep.all():
            return res.levels
        out, a = [], 0
        for x in res.levels:
            k = keep[a:a + len(x[0])]
            out.append(tuple(y[k] for y in x))
            a += len(x[0])
        return out

    def pack(self, params: RlfcParams, res: LoopResult) -> tuple[dict, list]:
        """Pack a closed-loop result into (config, sections)."""
        P, B = self.P, self.B
        levels = self.prune(res)
        if levels:
            g = np.concatenate([x[0] for x in levels])
            loc = np.concatenate([x[1] for x in levels])
            q = np.concatenate([x[2] for x in levels])
            raw = np.concatenate([x[3] for x in levels])
            raw_px = np.concatenate([x[4] for x in levels])
        else:
            g = loc = np.zeros(0, np.int64)
            q = np.zeros((0, P, B * B), np.int32)
            raw = np.zeros(0, bool)
            raw_px = np.zeros((0, B * B * self.lf.channels), np.int64)
        index, blocks, layout = blk.pack_runs(g, loc, q, raw, raw_px, self.n_res_nodes, self.nby * self.nbx, self.bps)
        top_cfg, top_bytes, off = [], [], 0
        for cd, data in res.top:
            top_cfg.append({"codec": cd, "offset": off, "length": len(data)})
            top_bytes.append(data)
            off += len(data)
        q16 = [params.q16] * P
        if P in (2, 4):
            q16[-1] = 16
        cfg = {
            "profile": self.strategy.profile, "params": params.to_dict(), "block_size": B, "planes": P,
            "channels": self.lf.channels, "dtype": str(self.dtype), "height": self.lf.height, "width": self.lf.width,
            "padded": [self.Hp, self.Wp], "blocks": [self.nby, self.nbx], "q16": q16,
            "tree": self.tree.to_config(), "n_res_nodes": self.n_res_nodes,
            "level_offset": [self.level_offset[lev] for lev in range(self.tree.height)],
            "top": top_cfg, "layout": layout, "n_blocks": int(len(g)), "n_raw_blocks": int(raw.sum()),
        }
        side_cfg, side_sections = self.strategy.side(self, params)
        cfg.update(side_cfg)
        sections = [("rlfc.top", b"".join(top_bytes))] + side_sections
        if self.strategy.index_coding == "zlib-runlen":
            cfg["index_coding"] = "zlib-runlen"
            sections.append(("rlfc.index", blk.pack_index(index)))
        else:
            sections.append(("rlfc.index", index.astype("<u4").tobytes()))
        sections.append(("rlfc.blocks", blocks.tobytes()))
        return cfg, sections

    def decoded_views(self, res: LoopResult) -> np.ndarray:
        """(R, C, H, W, Ch) pixels the file of ``res`` decodes to."""
        from formats.pixels import from_planes

        lf = self.lf
        px = from_planes(res.dec0[:, :lf.height, :lf.width], lf.views.dtype)
        return px.reshape(lf.views.shape)
