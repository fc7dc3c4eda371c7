"""RLFC encoder: key-view tree, closed-loop sparse residuals, BISE-packed blocks.

Data path: views (R, C, H, W, Ch) → padded to multiples of B → RKVs per level (Gaussian
filter, in the input's RGB domain) → top RKVs coded as images → top-down, per level:
residual = YCoCg-R(RKV) − decoded parent, thresholded and quantized; the decoded node is
rebuilt from the quantized residual (closed loop) → blocks packed per location.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from formats.errors import UnsupportedError
from formats.lightfield import LightField

from . import blocks as blk
from .color import plane_weights, to_planes
from .params import RlfcParams
from .residual import block_energy, from_blocks, quantize_dequantize, to_blocks
from .topcodec import decode_image, encode_image
from .disparity import dcp_clusters, estimate, pack_disparity, predict_views
from .tree import Tree, build_tree, filter_level

CODEC_ID = "rlfc"
CODEC_VERSION = 1
PRED_CACHE_BYTES = 1 << 30    # dcp: cache the (Q-independent) prediction of all views up to this size


@dataclass
class LoopResult:
    """What the closed loop produced for one parameter set (before packing)."""

    tree: Tree
    dec0: np.ndarray            # (N0, Hp, Wp, P) int32 decoded view planes
    levels: list                # per level l (H-1..0): (g, loc, q, raw, raw_px)
    top: list                   # [(codec, bytes)] per top node
    top_dec: np.ndarray         # (N_H, Hp, Wp, P) int32


def _pad(x: np.ndarray, b: int) -> np.ndarray:
    h, w = x.shape[-3:-1]
    ph, pw = -h % b, -w % b
    if ph == 0 and pw == 0:
        return x
    pad = [(0, 0)] * (x.ndim - 3) + [(0, ph), (0, pw), (0, 0)]
    return np.pad(x, pad, mode="edge")


class Encoder:
    """Holds the parameter-independent work (RKVs, top images) so rate control can re-run
    the closed loop for many quantizer settings cheaply."""

    def __init__(self, lf: LightField, params: RlfcParams, disparity: np.ndarray | None = None):
        """``disparity``: dcp only, a (n_clusters, n_blocks) map to use instead of estimating one
        (rate control re-uses one map across key-view qualities)."""
        if lf.views.dtype not in (np.uint8, np.uint16):
            raise UnsupportedError(f"RLFC codes 8- or 16-bit integer views; this light field is {lf.views.dtype} "
                                   "(convert float/EXR views to 16-bit first)")
        self.lf = lf
        self.B = params.block_size
        r, c, h, w, ch = lf.views.shape
        self.dtype = lf.views.dtype
        self.bps = lf.views.dtype.itemsize
        self.P = ch
        self.profile = params.profile
        self.frac_bits = int(params.disp_frac_bits)
        views = _pad(lf.views.reshape(r * c, h, w, ch), self.B)
        self.Hp, self.Wp = views.shape[1:3]
        self.rkv = [views]
        if self.profile == "dcp":
            if lf.layout != "grid":
                raise UnsupportedError("the dcp profile needs a grid of parallel cameras; use --profile bise "
                                       "for posed captures")
            par, key, self.offsets = dcp_clusters(r, c, lf.positions)
            pos = lf.positions.reshape(-1, 3)
            self.tree = Tree((par,), (r * c, len(key)), (pos, pos[key]))
            self.key_of = par
            self.rkv.append(views[key])                       # key views are views, not averages
        else:
            self.tree = build_tree(r, c, lf.positions, params.tree_height, lf.layout)
            for lev in range(self.tree.height):
                self.rkv.append(filter_level(self.rkv[-1], self.tree, lev, params.sigma))
        self.top = [encode_image(im, params.top_codec, params.top_psnr) for im in self.rkv[-1]]
        top_px = np.stack([decode_image(cd, data, im.shape, im.dtype) for (cd, data), im in zip(self.top, self.rkv[-1])])
        self.top_dec = to_planes(top_px)
        self.nby, self.nbx = self.Hp // self.B, self.Wp // self.B
        if self.profile == "dcp":
            self.disp = disparity if disparity is not None else estimate(
                to_planes(views), self.top_dec, self.key_of, self.offsets, self.B, int(params.max_disparity),
                self.frac_bits, smooth_tol=float(params.disp_smooth), smooth_iters=3 if params.disp_smooth > 0 else 0)
            # the prediction does not depend on the quantizer: keep it for rate control when it fits
            self._pred = None
            if views.size * 4 <= PRED_CACHE_BYTES:
                self._pred = predict_views(self.top_dec, self.key_of, self.offsets, self.disp,
                                           np.arange(len(views)), self.B, self.frac_bits)
        H = self.tree.height
        # BFS numbering of residual nodes: level H-1 first, level 0 last
        self.level_offset = {}
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
            par = self.tree.parents[lev]
            n_l = len(par)
            nxt = np.empty((n_l, self.Hp, self.Wp, P), dtype=np.int32)
            for a in range(0, n_l, 16):   # chunks of nodes bound the memory of one level
                s = slice(a, min(a + 16, n_l))
                if self.profile == "dcp" and self._pred is not None:
                    pred = self._pred[s]
                elif self.profile == "dcp":
                    pred = predict_views(self.top_dec, self.key_of, self.offsets, self.disp,
                                         np.arange(s.start, s.stop), B, self.frac_bits)
                else:
                    pred = dec[par[s]]
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
                    rawpx = to_blocks(self.rkv[lev][s], B)[kn[raw], ky[raw], kx[raw]].reshape(int(raw.sum()), B * B * self.lf.channels)
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
        res = LoopResult(res.tree, res.dec0, levels, res.top, res.top_dec)
        if res.levels:
            g = np.concatenate([x[0] for x in res.levels])
            loc = np.concatenate([x[1] for x in res.levels])
            q = np.concatenate([x[2] for x in res.levels])
            raw = np.concatenate([x[3] for x in res.levels])
            raw_px = np.concatenate([x[4] for x in res.levels])
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
            "profile": params.profile, "params": params.to_dict(), "block_size": B, "planes": P,
            "channels": self.lf.channels, "dtype": str(self.dtype), "height": self.lf.height, "width": self.lf.width,
            "padded": [self.Hp, self.Wp], "blocks": [self.nby, self.nbx], "q16": q16,
            "tree": self.tree.to_config(), "n_res_nodes": self.n_res_nodes,
            "level_offset": [self.level_offset[lev] for lev in range(self.tree.height)],
            "top": top_cfg, "layout": layout, "n_blocks": int(len(g)), "n_raw_blocks": int(raw.sum()),
        }
        sections = [("rlfc.top", b"".join(top_bytes))]
        if self.profile == "dcp":
            data, dt = pack_disparity(self.disp)
            cfg["dcp"] = {"offsets": self.offsets.tolist(), "max_disparity": int(params.max_disparity),
                          "frac_bits": self.frac_bits, "disp_coding": "zlib-delta", "disp_dtype": dt}
            sections.append(("rlfc.disp", data))
        if self.profile == "dcp":
            cfg["index_coding"] = "zlib-runlen"
            sections.append(("rlfc.index", blk.pack_index(index)))
        else:
            sections.append(("rlfc.index", index.astype("<u4").tobytes()))
        sections.append(("rlfc.blocks", blocks.tobytes()))
        return cfg, sections


def encode(lf: LightField, params: RlfcParams | None = None) -> tuple[dict, list, LoopResult]:
    """Encode a light field with fixed parameters.

    Returns:
        (config, sections, loop result); ``loop.dec0`` holds the decoded view planes.
    """
    params = params or RlfcParams()
    enc = Encoder(lf, params)
    res = enc.closed_loop(params)
    cfg, sections = enc.pack(params, res)
    return cfg, sections, res
