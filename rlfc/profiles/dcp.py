"""Profile ``dcp``: disparity-compensated prediction from 3×3-cluster key views, BISE-packed
residual blocks (grids only).

Each 3×3 cluster's most central view is its key view, coded as an image (lossy JPEG 2000 by
default). Every view is predicted block by block from its key view shifted by d·(grid offset),
d one sub-pixel disparity per (cluster, block) in a ``rlfc.disp`` section; residuals as in
``bise``. One block of one view = the in-memory key view + at most one stored block.
Rate knob: the key views' quality first (prediction only), then the quantizer.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from formats.codec_api import EncodeOptions
from formats.errors import FormatError, UnsupportedError

from ..disparity import (dcp_clusters, estimate, pack_disparity, planar, predict_blocks, predict_views,
                         unpack_disparity)
from ..kernels import bilinear
from ..keytree import KeyStrategy, KeyTreeEncoder
from ..keytree_decode import DecodeStrategy, KeyTreeDecoder
from ..ratecontrol import Q_MAX, bisect, depth_scale, loop_psnr, params_for_quant, search_quant
from ..tree import Tree
from .base import Profile
from .keyfamily import encode_keyfamily

PRED_CACHE_BYTES = 1 << 30    # cache the (Q-independent) prediction of all views up to this size


class DisparityKeys(KeyStrategy):
    """Encoder side: key views are the clusters' central views; prediction shifts them."""

    profile = "dcp"
    index_coding = "zlib-runlen"

    def build(self, enc, lf, views, params):
        r, c = lf.rows, lf.cols
        par, key, enc.offsets = dcp_clusters(r, c, lf.positions)
        pos = lf.positions.reshape(-1, 3)
        enc.key_of = par
        enc.frac_bits = int(params.disp_frac_bits)
        return Tree((par,), (r * c, len(key)), (pos, pos[key])), [views[key]]

    def prepare(self, enc, params, side=None):
        from formats.pixels import to_planes

        enc.disp = side if side is not None else estimate(
            to_planes(enc.views), enc.top_dec, enc.key_of, enc.offsets, enc.B, int(params.max_disparity),
            enc.frac_bits, smooth_tol=float(params.disp_smooth), smooth_iters=3 if params.disp_smooth > 0 else 0)
        enc.top_planar = planar(enc.top_dec)
        enc.pred = None            # the prediction does not depend on the quantizer: keep it when it fits
        if enc.views.size * 4 <= PRED_CACHE_BYTES:
            enc.pred = predict_views(enc.top_dec, enc.key_of, enc.offsets, enc.disp, np.arange(len(enc.views)),
                                     enc.B, enc.frac_bits, enc.top_planar)

    def predict(self, enc, level, nodes, dec_above):
        if enc.pred is not None:
            return enc.pred[nodes]
        return predict_views(enc.top_dec, enc.key_of, enc.offsets, enc.disp, nodes, enc.B, enc.frac_bits,
                             enc.top_planar)

    def side(self, enc, params):
        data, dt = pack_disparity(enc.disp)
        return ({"dcp": {"offsets": enc.offsets.tolist(), "max_disparity": int(params.max_disparity),
                         "frac_bits": enc.frac_bits, "disp_coding": "zlib-delta", "disp_dtype": dt}},
                [("rlfc.disp", data)])


class DisparityPrediction(DecodeStrategy):
    """Decoder side: the same integers as the encoder's prediction, numpy or torch."""

    def open(self, dec, cfg, container):
        name = container.name
        dcp = cfg.sub("dcp")
        n0, n_top = dec.n_views, dec.tree.sizes[-1]
        if dec.levels != 1:
            raise FormatError(f"{name}: dcp files have a tree of height 1, this one has {dec.levels}")
        offs = dcp.list("offsets", max_len=n0)
        rows, cols = dec.hdr.rows, dec.hdr.cols
        if len(offs) != n0 or any(not isinstance(o, list) or len(o) != 2 or
                                  not all(isinstance(x, int) and not isinstance(x, bool) for x in o) or
                                  not (0 <= v // cols - o[0] < rows and 0 <= v % cols - o[1] < cols)
                                  for v, o in enumerate(offs)):
            raise FormatError(f"{name}: config.dcp.offsets must hold {n0} integer pairs, view-to-key steps to a key "
                              f"view inside the {rows}x{cols} grid")
        self.offsets = np.asarray(offs, dtype=np.int64).reshape(n0, 2)
        self.F = dcp.int("frac_bits", 0, 4)
        dcp.str("disp_coding", choices=("zlib-delta",))
        dt = dcp.str("disp_dtype", choices=("<i1", "<i2"))
        self.key_of = dec.tree.parents[0]
        self.disp = unpack_disparity(bytes(container.read("rlfc.disp")), dt, (n_top, dec.nby * dec.nbx), name)
        self.B, self.hw, self.nbx = dec.block_size, (dec.Hp, dec.Wp), dec.nbx
        self.top_planar = planar(dec.top)                    # (P, n_top·Hp·Wp): fast per-plane gathers

    def arrays(self, dec):
        return {"tp": self.top_planar, "disp": self.disp, "offsets": self.offsets, "key_of": self.key_of}

    def predict_blocks(self, st, xp, views, by, bx):
        return predict_blocks(xp, st["tp"], self.hw, st["key_of"], st["offsets"], st["disp"], views, by, bx,
                              self.B, self.nbx, self.F)

    def predict_one(self, dec, v, by, bx):
        """Python-int arithmetic and a slice of the key view (no per-request arrays)."""
        B, F = self.B, self.F
        k = int(self.key_of[v])
        d = int(self.disp[k, by * self.nbx + bx])
        Y, X = ((by * B) << F) + d * int(self.offsets[v, 0]), ((bx * B) << F) + d * int(self.offsets[v, 1])
        y0, x0, m = Y >> F, X >> F, (1 << F) - 1
        img = dec.top[k]
        hp, wp = self.hw
        if 0 <= y0 and y0 + B < hp and 0 <= x0 and x0 + B < wp:
            win = img[y0:y0 + B + 1, x0:x0 + B + 1]
        else:   # clamp at the padded image's edges
            ys = np.clip(np.arange(y0, y0 + B + 1), 0, hp - 1)
            xs = np.clip(np.arange(x0, x0 + B + 1), 0, wp - 1)
            win = img[ys[:, None], xs[None, :]]
        return np.moveaxis(bilinear(np.moveaxis(win, -1, 0), Y & m, X & m, F), 0, -1).reshape(B * B, dec.P)

    def predict_nodes(self, dec, level, ids, above, above_ids):
        # the level above is always every key view, decoded at open
        return predict_views(dec.top, self.key_of, self.offsets, self.disp, ids, self.B, self.F, self.top_planar)


def _encoders(lf, base):
    """dcp encoders at different key-view PSNRs sharing one disparity map, estimated by the first
    encoder built (callers build the best key views first)."""
    state = {"disp": None}

    def make(top_psnr):
        p = replace(base, top_psnr=top_psnr)
        enc = KeyTreeEncoder(lf, p, DisparityKeys(), side=state["disp"])
        state["disp"] = enc.disp
        return enc, p
    return make


def search_psnr(lf, base, options, progress, *, margins=(-1.0, 6.0), tol=0.25, residual_steps=(0.5,)):
    """The key views' quality is the main knob.

    With sub-pixel disparity the prediction alone often meets the target, and key-view bits are
    cheaper than residual blocks. So: (1) bisect the key views' PSNR (target + m dB, m in
    ``margins``) for the cheapest key views whose prediction alone meets the target (Q at its
    coarsest: no residual blocks); (2) for m* − each of ``residual_steps``, search Q (key views a
    little worse, residual blocks make up the difference); the smallest file that meets the
    target wins. When even the best key views miss the target, Q is searched at margins 3 and
    1 dB. The disparity map is estimated once (against the best key views) and re-used.
    """
    target = options.target_psnr
    thr, eng = options.params.get("threshold"), options.params.get("energy")
    trace = []
    coarse_q = Q_MAX * depth_scale(lf.views.dtype)
    make = _encoders(lf, base)

    def size(enc, p, res):
        return sum(len(s) for _, s in enc.pack(p, res)[1])

    def coarse(m):
        enc, p0 = make(target + m)
        p = params_for_quant(p0, coarse_q, thr, eng)
        res = enc.closed_loop(p, keep_blocks=False)
        ps = loop_psnr(enc, res)
        trace.append({"top_psnr": target + m, "quant": p.quant, "psnr_rgb": ps, "bpp": None})
        progress(len(trace), p, ps, None)
        return ps >= target, (enc, p)

    def with_residuals(m):
        enc, p0 = make(target + m)
        ok, p, res, tr = search_quant(enc, p0, target_psnr=target, fixed_threshold=thr, fixed_energy=eng,
                                      progress=progress)
        trace.extend({"top_psnr": target + m, **t} for t in tr)
        return ok, enc, p, res

    lo, hi = margins
    found, m_best, (enc, p), _ = bisect(coarse, hi, lo, iters=16, tol=tol)
    if not found:                                   # prediction alone never suffices: residuals needed
        best = None
        for m in (3.0, 1.0):
            ok, enc, p, res = with_residuals(m)
            sz = size(enc, p, res)
            if best is None or (ok, -sz) > (best[0], -best[1]):
                best = (ok, sz, enc, p, res)
        return best[0], best[2], best[3], best[4], trace
    res = enc.closed_loop(p)
    best = (size(enc, p, res), enc, p, res)
    for step in residual_steps:
        if m_best - step < margins[0]:
            continue
        ok, enc, p, res = with_residuals(m_best - step)
        sz = size(enc, p, res)
        if ok and sz < best[0]:
            best = (sz, enc, p, res)
    return True, best[1], best[2], best[3], trace


def search_bpp(lf, base, options, progress, *, db_range=(10.0, 50.0), iters=8, meta_bytes=4096):
    """For a bpp ceiling: bisect the key views' PSNR for the best key views whose prediction-only
    file fits; when even the best key views fit, search Q to spend the rest on residual blocks."""
    from formats.metrics import bpp as bpp_of

    target = options.target_bpp
    nv = lf.rows * lf.cols
    coarse_q = Q_MAX * depth_scale(lf.views.dtype)
    trace = []
    make = _encoders(lf, base)

    def evaluate(db):
        enc, p0 = make(db)
        p = params_for_quant(p0, coarse_q)
        res = enc.closed_loop(p)
        b = bpp_of(sum(len(s) for _, s in enc.pack(p, res)[1]) + meta_bytes, nv, lf.height, lf.width)
        ps = loop_psnr(enc, res)
        trace.append({"top_psnr": db, "quant": p.quant, "psnr_rgb": ps, "bpp": b})
        progress(len(trace), p, ps, b)
        return b <= target, (enc, p, res)

    lo, hi = db_range
    ok, (enc, p, res) = evaluate(hi)
    if ok:                                       # room for residual blocks on top of the best key views
        found, p2, res2, tr = search_quant(enc, replace(base, top_psnr=hi), target_bpp=target,
                                           meta_bytes=meta_bytes, progress=progress)
        trace.extend({"top_psnr": hi, **t} for t in tr)
        return found, enc, p2, res2, trace
    found, _, (enc, p, res), _ = bisect(evaluate, lo, hi, iters=iters)
    return found, enc, p, res, trace


class DcpProfile(Profile):
    id = "dcp"
    description = "disparity-compensated prediction from 3x3-cluster key views, BISE residual blocks (grids)"
    OWN = {"max_disparity", "disp_frac_bits", "disp_smooth"}

    def accepts(self, lf):
        if lf.layout != "grid":
            return "the dcp profile needs a grid of parallel cameras (this capture is posed)"
        return None

    def strategy(self, lf=None) -> DisparityKeys:
        why = self.accepts(lf) if lf is not None else None
        if why:
            raise UnsupportedError(f"{why}; use --profile bise")
        return DisparityKeys()

    def encode(self, lf, options: EncodeOptions, progress=None):
        self.strategy(lf)
        lossless = options.lossless or options.params.get("quant") in (1, 1.0)
        defaults = {}
        if not lossless and options.params.get("top_psnr") is None:
            # dcp key views are lossy: searched with a target, 44 dB without
            defaults["top_psnr"] = options.target_psnr + 3 if options.target_psnr is not None else 44.0
        search = None
        if options.params.get("top_psnr") is None and not lossless:
            if options.target_psnr is not None:
                search = search_psnr
            elif options.target_bpp is not None:
                search = search_bpp
        return encode_keyfamily(lf, options, DisparityKeys(), progress, search, self.OWN, defaults)

    def open(self, container, header, cfg, limits=None):
        return KeyTreeDecoder(container, header, cfg, DisparityPrediction(), limits)


PROFILE = DcpProfile()
