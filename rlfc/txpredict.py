"""Prediction of the ``tx`` profile, in integers (numpy or torch via :mod:`rlfc.xp`).

Multi-reference disparity compensation: an 8×8 block at pixel (y0, x0) of view v, with
disparity d (units 1/16 pixel per view step) and reference key views k_j at grid positions
pos_j, samples key k_j at (y0 + y, x0 + x)·16 + d·(pos_v − pos_j) in 1/16 pixel, bilinearly
(:func:`rlfc.kernels.bilinear`, F = 4, one (9×9) window per reference), giving p_j. With
weights w_j (integers summing to 64) the prediction is (Σ_j w_j·p_j + 32) >> 6; a block in
"single reference j" mode uses w = 64 on reference j (so the prediction is p_j exactly).

Intra views (no references) are predicted by the bilinear upsampling of a thumbnail (one
value per 8×8 block and plane): pixel y samples thumbnail row (2y − 7)/16 (likewise x),
clamped at the edges, bilinear with F = 4.
"""
from __future__ import annotations

import numpy as np

from .kernels import bilinear
from .txlayout import weighted_planes
from .xp import NUMPY

TB = 8            # transform / prediction block edge
DISP_BITS = 4     # disparities and sample positions in 1/16 pixel
W_BITS = 6        # blend weights sum to 64


def mode_weights(weights: np.ndarray) -> np.ndarray:
    """Blend weights per tb mode: (…, R) blend weights → (…, R + 1, R): mode 0 blends with
    ``weights``, mode k puts all 64 on reference k − 1 (index it with the modes)."""
    w = np.asarray(weights)
    R = w.shape[-1]
    one = np.broadcast_to(64 * np.eye(R, dtype=w.dtype), w.shape[:-1] + (R, R))
    return np.concatenate([w[..., None, :], one], axis=-2)


def planar(planes: np.ndarray) -> np.ndarray:
    """(n, Hp, Wp, P) planes → (P, n·Hp·Wp) contiguous (fast gathers)."""
    return np.ascontiguousarray(np.moveaxis(planes, -1, 0)).reshape(planes.shape[-1], -1)


def predict_tbs(xp, kp, hw, slots, weights, disp_y, disp_x, y0, x0):
    """Prediction of M 8×8 blocks from up to R references each.

    Args:
        kp: (P, n_keys·Hp·Wp) int32 planar decoded key views; hw: (Hp, Wp).
        slots: (M, R) key index of each reference (any valid index where the weight is 0).
        weights: (M, R) int weights summing to 64 per block.
        disp_y, disp_x: (M, R) displacements of each reference in 1/16 pixel.
        y0, x0: (M,) block origins in pixels.

    Returns:
        (M, 8, 8, P) int32.
    """
    hp, wp = hw
    M, R = slots.shape
    F = DISP_BITS
    groups = None
    if isinstance(weights, np.ndarray):                 # numpy: gather only the references that count,
        nz = weights > 0                                # blocks grouped by how many (reshape + sum, no scatter)
        cnt = nz.sum(1)
        order = np.argsort(cnt, kind="stable")
        groups = [(c, order[cnt[order] == c]) for c in np.unique(cnt).tolist()]
        m = np.concatenate([np.repeat(g, c) for c, g in groups]) if groups else np.zeros(0, np.int64)
        r = np.concatenate([np.nonzero(nz[g])[1] for c, g in groups]) if groups else np.zeros(0, np.int64)
    else:
        m, r = xp.arange(M).repeat_interleave(R), xp.arange(R).repeat(M)
    Y = (y0[m] << F) + disp_y[m, r]                                               # (N,)
    X = (x0[m] << F) + disp_x[m, r]
    ext = xp.arange(TB + 1)
    rows = ((Y >> F)[:, None] + ext).clip(0, hp - 1)                              # (N, 9)
    cols = ((X >> F)[:, None] + ext).clip(0, wp - 1)
    idx = ((slots[m, r] * hp)[:, None, None] + rows[:, :, None]) * wp + cols[:, None, :]
    win = xp.take_cols(kp, idx)                                                   # (P, N, 9, 9)
    fy = xp.cast(Y & ((1 << F) - 1), xp.int32)[None, :, None, None]
    fx = xp.cast(X & ((1 << F) - 1), xp.int32)[None, :, None, None]
    p = bilinear(win, fy, fx, F) * xp.cast(weights[m, r], xp.int32)[None, :, None, None]   # (P, N, 8, 8)
    if groups is not None:
        acc = np.empty((p.shape[0], M, TB, TB), np.int32)
        a = 0
        for c, g in groups:
            acc[:, g] = p[:, a:a + c * g.size].reshape(p.shape[0], g.size, c, TB, TB).sum(2)
            a += c * g.size
    else:
        acc = p.reshape(p.shape[0], M, R, TB, TB).sum(2)
    return xp.moveaxis((acc + (1 << (W_BITS - 1))) >> W_BITS, 0, -1)


def upsample_thumb(thumb: np.ndarray, hp: int, wp: int, xp=NUMPY):
    """(ty, tx, P) thumbnail values → (hp, wp, P) int32 bilinear prediction (see module doc)."""
    ty, tx = thumb.shape[:2]
    F = DISP_BITS

    def axis(n, m):
        q = 2 * np.arange(n, dtype=np.int64) - 7
        i0 = q >> F
        return np.clip(i0, 0, m - 1), np.clip(i0 + 1, 0, m - 1), q & ((1 << F) - 1)

    ya, yb, fy = axis(hp, ty)
    xa, xb, fx = axis(wp, tx)
    t = thumb.astype(np.int32)
    s = 1 << F
    # separable: the horizontal pass on the thumbnail's rows, then the rows gathered (the same
    # integers as gathering first: a row gather commutes with the horizontal blend)
    fxv = fx.astype(np.int32)[None, :, None]
    h = t[:, xa] * (s - fxv)
    h += t[:, xb] * fxv                                          # (ty, wp, P)
    fyv = fy.astype(np.int32)[:, None, None]
    out = h[ya] * (s - fyv)
    out += h[yb] * fyv
    out += 1 << (2 * F - 1)
    out >>= 2 * F
    return out


def weigh(pred: np.ndarray, gain, offset, lo, hi) -> np.ndarray:
    """A weighted prediction (``tx`` version 4): ((pred·gain + 32) >> 6) + offset, clipped to
    [lo, hi], returned: in place on ``pred`` where it is C-contiguous int32 (else on a copy);
    (…, P) with a multiple of 64·P samples (8×8 blocks or whole views); ``gain`` (1/64, 32..96) and ``offset`` per plane (P,), or per row of 64·P
    samples (M, P) (one 8×8 block each); ``lo``, ``hi`` (P,). The values are tiled over a
    row so numpy's inner loops run 64·P samples, not P. Products stay below 2^31: planes are
    within ±2^16, gains below 2^7."""
    P = pred.shape[-1]
    if not pred.flags.c_contiguous or pred.dtype != np.int32:
        pred = np.ascontiguousarray(pred, np.int32)         # (the result is the returned array)
    flat = pred.reshape(-1, 64 * P)

    def tiled(a):
        a = np.asarray(a, np.int32)
        return np.tile(a, 64) if a.ndim <= 1 else np.tile(a.reshape(-1, P), (1, 64))

    np.multiply(flat, tiled(gain), out=flat)
    # ((x + 32) >> 6) + o = (x + 32 + 64·o) >> 6 (an arithmetic shift floors: adding a multiple of
    # 64 before it adds its 64th after): one pass less (|x| < 2^23, |64·o| < 2^24)
    flat += tiled(32 + 64 * np.asarray(offset, np.int32))
    flat >>= 6
    np.minimum(np.maximum(flat, tiled(lo), out=flat), tiled(hi), out=flat)
    return pred


#: the samples a weighted prediction is fitted on: every FIT_STRIDE-th (coprime with a tb's 8 columns)
FIT_STRIDE = 5
#: the share of a plane's prediction error a fit must take away to be kept
FIT_MIN_GAIN = 0.02
#: and error worth this many bits at the view's λ (weight · mean squared error taken away ·
#: samples / λ): a kept plane's gain and offset cost about 30 bits in ``tx.layout``, and part of
#: the error a fit takes away is in 8×8 blocks coded either way (BENCHMARKS.md, weighted
#: prediction: hci_antinous at 40 dB kept 11 chroma planes worth 14–119 bits each, which saved
#: 136 bits together and cost 328; stanford_chess's kept planes are worth 131–14 160 bits,
#: lytro_dino_2067's 565–27 256)
FIT_PRICE_BITS = 128


def fit_price(lam: float, w, samples: int) -> np.ndarray:
    """(P,) the mean squared error per sample a plane's fit must take away to pay for itself
    (:data:`FIT_PRICE_BITS` at ``lam``, error per bit) in a view of ``samples`` samples per plane
    whose planes weigh ``w`` (P,) in the error (``inf`` where a plane does not count)."""
    w = np.asarray(w, np.float64)
    return np.where(w > 0, lam * FIT_PRICE_BITS / (np.where(w > 0, w, 1.0) * samples), np.inf)


def fit_weights(pred: np.ndarray, orig: np.ndarray, lo, hi, price=None) -> np.ndarray:
    """(P, 2) int64 gain (1/64, within 32..96) and offset per plane that bring ``pred`` closest
    to ``orig`` (both (…, P) int32 planes of one view) in the least-squares sense, quantized: the
    encoder's fit for :func:`weigh` (any fit decodes; this one only has to be good). ``price``
    (P,): the mean squared error per sample a plane's fit must take away, besides
    :data:`FIT_MIN_GAIN` of it, to be kept (``inf``: never; :func:`fit_price`)."""
    P = pred.shape[-1]
    # every FIT_STRIDE-th sample (a fit needs moments, not every pixel), plane by plane (P, n):
    # raw moments, exact in float64 (integer products below 2^34, sums below 2^53)
    x = np.ascontiguousarray(pred.reshape(-1, P)[::FIT_STRIDE].T, dtype=np.float64)
    y = np.ascontiguousarray(orig.reshape(-1, P)[::FIT_STRIDE].T, dtype=np.float64)
    n = x.shape[1]
    mx, my = x.sum(1) / n, y.sum(1) / n
    vx = np.einsum("pn,pn->p", x, x) / n - mx * mx
    cov = np.einsum("pn,pn->p", x, y) / n - mx * my
    g = np.where(vx > 0, cov / np.where(vx > 0, vx, 1.0), 1.0)
    gq = np.clip(np.rint(g * 64), 32, 96).astype(np.int64)
    o = np.rint(my - gq / 64 * mx).astype(np.int64)
    o = np.clip(o, -(np.asarray(hi) - np.asarray(lo)), np.asarray(hi) - np.asarray(lo))
    # a plane keeps its fit only where it takes FIT_MIN_GAIN of the prediction's squared error
    # away (E[(y − a·x − o)²] from the moments, a = gq/64); else the identity
    sxx, sxy, syy = vx + mx * mx, cov + mx * my, np.einsum("pn,pn->p", y, y) / n
    a = gq / 64

    def err(a, o):
        return syy - 2 * a * sxy - 2 * o * my + a * a * sxx + 2 * a * o * mx + o * o

    e0, e1 = err(1.0, 0.0), err(a, o)
    keep = e0 - e1 > FIT_MIN_GAIN * np.maximum(e0, 1e-9)
    if price is not None:
        keep &= e0 - e1 > np.asarray(price, np.float64)
    return np.stack([np.where(keep, gq, 64), np.where(keep, o, 0)], axis=-1)


#: what a kept plane's gain and offset cost in ``tx.layout``, in bits
FIT_PLANE_BITS = 30
#: the error (weighted, per 8×8 block and plane) worth this many bits at the view's λ is where a
#: block stops being skipped: below it, error taken away is distortion saved; above it, the block
#: is coded and its error costs bits, about FIT_CAP_BITS per e-fold of it
FIT_CAP_BITS = 8


def _rd_cost(e: np.ndarray, cap: float) -> np.ndarray:
    """The estimated rate-distortion cost (error units) of 8×8 blocks' prediction errors ``e``:
    e where e ≤ cap, else cap·(1 + ln(e / cap)) (continuous, with its slope)."""
    return np.where(e <= cap, e, cap * (1 + np.log(np.maximum(e, cap) / cap)))


def priced_weights(pt: np.ndarray, orig: np.ndarray, wp: np.ndarray, w, lam: float, lo, hi):
    """The planes of the fit ``wp`` (P, 2) (from :func:`fit_weights`) that pay for their
    parameters, and the prediction they give: (wp, or None where no plane pays or the fit is the
    identity; the prediction (T, 8, 8, P) int32). ``pt``, ``orig`` (T, 8, 8, P) int32 tbs of one view (``pt`` is weighed
    in place where a fit is kept); ``w`` (P,) the planes' error weights; ``lam`` the view's λ
    (error per bit). A plane's saving is Σ over its 8×8 blocks of :func:`_rd_cost` of its
    weighted squared error without the fit minus with it, against λ·FIT_PLANE_BITS: a fit that
    takes error away from blocks coded either way (an occluder, a misprediction) while adding
    a little to blocks that would be skipped is refused."""
    fitted = weighted_planes(wp)
    if not fitted.any():
        return None, pt
    P = pt.shape[-1]
    cap = lam * FIT_CAP_BITS
    # (T, 64·P) squared errors in float32 → per-plane sums (T, P) as one product with a 0/1
    # matrix, weighted (a decision: float32 is enough, and 10× faster than float64 reductions)
    sel = np.tile(np.eye(P, dtype=np.float32), (TB * TB, 1)) * np.asarray(w, np.float32)

    def cost(p, o):
        d = (o - p).reshape(p.shape[0], TB * TB * P).astype(np.float32)
        d *= d
        return _rd_cost((d @ sel).astype(np.float64), cap).sum(0)

    # on every FIT_STRIDE-th 8×8 block (a sum over blocks: a sample of them estimates it)
    ps, os_ = pt[::FIT_STRIDE], orig[::FIT_STRIDE]
    saved = (cost(ps, os_) - cost(weigh(ps.copy(), wp[:, 0], wp[:, 1], lo, hi), os_)) * FIT_STRIDE
    keep = fitted & (saved > lam * FIT_PLANE_BITS)
    if not keep.any():
        return None, pt
    wp = np.where(keep[:, None], wp, np.array([64, 0]))
    return wp, weigh(pt, wp[:, 0], wp[:, 1], lo, hi)
