"""Open-loop estimation of the ``tx`` maps: per cell of views and 8×8 block, the disparity
(1/16 px per view step) and the prediction mode (0 = blend, 1 + j = reference j) that
minimise the cell's luma error against the original key views.

Coarse to fine: whole-pixel disparities by shifting whole views (OpenCV, fast), widened from
±4 up to ``max_disparity`` while many blocks sit at the edge of the range and widening pays;
then ±1/2 (twice), ±1/4, ±1/8, ±1/16 px around each block's best (one cost evaluation per step
and sign serves both the shared map and each cell's own values), each reference warped per block at
the decoder's 1/16-px positions (OpenCV remap in float; the decoder's integer rounding is left
out of an estimate that only ranks candidates: 3.3× faster than the integer predictor, files
0.1–0.5% smaller or +0.07% on the six dense grids, BENCHMARKS.md); then the map is regularized
(its 3×3 median where that costs little more). The costs come from :class:`rlfc.txcosts.Estimator`.

With per-view warps (``struct.warp``, :mod:`rlfc.txwarp`) the refinement samples each reference
through them (each 8×8 block's offset, as the decoder's predictor); the whole-pixel sweep does
not (its candidates are a pixel apart, the warps' offsets a pixel or two at most).
"""
from __future__ import annotations

import numpy as np

from .txcosts import Estimator
from .txlayout import MAX_REFS

#: bits a cell's own disparity for a block, or a block's single-reference mode, is taken to cost
#: (about what they cost coded: BENCHMARKS.md)
SIDE_BITS = 6.0


def _mode_penalty(side_lambda: float, ref_modes: bool) -> np.ndarray:
    """(1, 1 + MAX_REFS, 1) cost added to each mode's error: 0 for the blend, SIDE_BITS bits at
    ``side_lambda`` for a single reference (never one where ``ref_modes`` is False)."""
    pen = np.zeros((1, 1 + MAX_REFS, 1))
    pen[0, 1:] = SIDE_BITS * side_lambda if ref_modes else np.inf
    return pen


def estimate_maps(luma: np.ndarray, struct, *, max_disparity: float = 64.0, start: float = 4.0,
                  side_lambda: float = 10.0, progress=None, runner=None, ref_modes: bool = True,
                  with_costs: bool = False):
    """One shared disparity map plus per-cell corrections and prediction modes.

    Returns:
        base (nloc8,) and per-map disparities (n_maps, nloc8), int64 in 1/16 px per view step
        (map m's disparity = base + its correction), and modes (n_maps, nloc8) int64.

    ``side_lambda``: luma squared error worth one bit of side information (the encoder's λ at
    the expected quality). A cell leaves the shared disparity, or a block leaves the blend, only
    where its error drops by more than the bits that costs (about 6 each); the shared map takes
    its neighbours' median where that costs less than about 2 bits. ``runner``: where the cells'
    costs are computed (:class:`formats.parallel.Runner`; the maps do not depend on it).
    ``ref_modes=False``: every block blends its references (mode 0; an ablation).
    ``with_costs``: also return every mode's costs at the returned disparities, (n_maps,
    1 + MAX_REFS, nloc8) float64 (what :func:`reprice_maps_both` would evaluate first; a block's
    costs depend on its own disparity only, so those kept as the blocks moved are those).
    """
    est = Estimator(luma, struct, list(struct.keys))
    n_maps = len(est.cells)
    nloc8 = est.nby8 * est.nbx8
    if n_maps == 0:
        z = np.zeros((0, nloc8), np.int64)
        return np.zeros(nloc8, np.int64), z, z
    pen_delta = SIDE_BITS * side_lambda
    pen = _mode_penalty(side_lambda, ref_modes)

    def best_mode(c):                       # (n_maps, modes, nloc8) → (n_maps, nloc8) cost with the best mode
        return (c + pen).min(axis=1)

    D = min(start, max_disparity)
    cands = list(np.arange(-D, D + 1))
    costs = est.costs_global_many(cands, runner, reduce=best_mode)
    if progress:
        progress("disparity", len(costs), None)
    while D < max_disparity:               # widen where blocks sit at the range's edge and it pays
        c = np.stack(costs)                                   # (nd, n_maps, nloc8)
        g = c.sum(1)
        at_edge = np.abs(np.asarray(cands)[g.argmin(0)]) == D
        if at_edge.mean() <= 0.02:
            break
        D2 = min(2 * D, max_disparity)
        more = list(np.arange(-D2, -D)) + list(np.arange(D + 1, D2 + 1))
        mc = est.costs_global_many(more, runner, reduce=best_mode)
        if progress:
            progress("disparity", len(costs) + len(mc), None)
        if np.minimum(np.stack(mc).sum(1).min(0), g.min(0)).sum() >= 0.995 * g.min(0).sum():
            break
        cands, costs, D = cands + more, costs + mc, D2
    c = np.stack(costs)                                        # (nd, n_maps, nloc8)
    cand16 = (np.asarray(cands) * 16).astype(np.int64)
    base = cand16[c.sum(1).argmin(0)]                          # the shared map: best over all cells
    own = cand16[c.argmin(0)]                                   # each cell's own best
    take = c.min(0) + pen_delta < np.take_along_axis(c, c.sum(1).argmin(0)[None, None, :].repeat(n_maps, 1), 0)[0]
    disp = np.where(take, own, base[None, :])
    lim = int(D * 16)

    def total(dmaps):                # (every mode's costs, the best mode's) of per-block disparities
        f = est.costs_maps(dmaps, runner)                      # (n_maps, 1 + MAX_REFS, nloc8)
        return f, best_mode(f)                                 # (n_maps, nloc8)

    full, cur = total(disp)            # (a block's costs depend on its own disparity only: every
    #                                    block's costs at its final disparity are kept as it moves)
    # refine the shared map, then each cell's own values, from one evaluation per step and sign:
    # a block's cost depends only on its own disparity, so the costs of every cell one step
    # along (dc) are also those of the shared map's candidate for the cells that follow it.
    # (The half-pixel step twice: a block the shared map moved takes no second step in the same
    # round; with one round of each step stanford_chess's file was 0.8% larger.)
    for step in (8, 8, 4, 2, 1):
        for sgn in (-1, 1):
            dc = np.clip(disp + sgn * step, -lim, lim)
            fc, cc = total(dc)
            follow = disp == base[None, :]
            gain = np.where(follow, cur - cc, 0).sum(0) > 0       # the shared map moves here
            base = np.where(gain, np.clip(base + sgn * step, -lim, lim), base)
            upd = follow & gain[None, :]
            disp, cur, full = np.where(upd, dc, disp), np.where(upd, cc, cur), np.where(upd[:, None], fc, full)
            # each cell's own value, where that pays its side cost (blocks the shared map moved
            # have taken this step already; the next, finer step refines them)
            better = ~upd & (cc + pen_delta * (dc != base[None, :]) < cur + pen_delta * (disp != base[None, :]))
            disp, cur, full = np.where(better, dc, disp), np.where(better, cc, cur), np.where(better[:, None], fc, full)
        if progress:
            progress("disparity", len(costs) + 2 * (5 - step.bit_length()), None)
    base, disp, cur, full = _regularize(est, total, base, disp, cur, full, side_lambda)
    modes = (full + pen).argmin(axis=1)
    est.drop_handle()                  # (a cycle through the runner's handle kept the luma alive)
    return (base, disp, modes, full) if with_costs else (base, disp, modes)


def _regularize(est: Estimator, total, base, disp, cur, full, side_lambda: float):
    """The shared map's 3×3 median where it costs less than ~2 bits more overall (twice), for
    the blocks that follow it: (base, disp, cur, full) updated (``total``: per-block
    disparities → (every mode's costs, the best mode's))."""
    nby8, nbx8 = est.nby8, est.nbx8
    for _ in range(2):
        g = np.pad(base.reshape(nby8, nbx8), 1, mode="edge")
        med = np.sort(np.stack([g[1 + dy:1 + dy + nby8, 1 + dx:1 + dx + nbx8] for dy in (-1, 0, 1)
                                for dx in (-1, 0, 1)]), axis=0)[4].reshape(-1)
        follow = disp == base[None, :]
        cand = np.where(follow, med[None, :], disp)
        fc, cc = total(cand)
        ok = (np.where(follow, cc - cur, 0).sum(0) <= 2.0 * side_lambda) & (med != base)
        base = np.where(ok, med, base)
        upd = follow & ok[None, :]
        disp, cur, full = np.where(upd, cand, disp), np.where(upd, cc, cur), np.where(upd[:, None], fc, full)
    return base, disp, cur, full


def reprice_maps(luma: np.ndarray, struct, base: np.ndarray, disp: np.ndarray, *, side_lambda: float,
                 correction_lambda: float, runner=None, ref_modes: bool = True, modes_too: bool = False,
                 costs: np.ndarray | None = None):
    """Maps of :func:`estimate_maps` (at ``side_lambda``) with each cell's own disparity judged
    again at ``correction_lambda`` (larger): dropped for the shared one where it no longer pays
    its side cost. The shared map's regularization stays at ``side_lambda``, and so do the modes
    unless ``modes_too``: a block seen by one reference only (an occlusion) needs its mode
    whatever λ is, but at a coarse enough step a mode's bits can cost more than it saves. Four
    cost evaluations instead of an estimation's 15 or more (rate control learns the coding λ
    only after its probe pass; :func:`rlfc.txrate._maps_pay_repriced` checks the result coded).

    ``costs``: every mode's costs at ``disp`` where the caller has them (``estimate_maps(...,
    with_costs=True)``): then three evaluations.

    Returns:
        (base, disp, modes) as :func:`estimate_maps`.
    """
    base, disp, modes, modes_repriced = reprice_maps_both(luma, struct, base, disp, side_lambda=side_lambda,
                                                          correction_lambda=correction_lambda, runner=runner,
                                                          ref_modes=ref_modes, costs=costs)
    return base, disp, modes_repriced if modes_too else modes


def reprice_maps_both(luma: np.ndarray, struct, base: np.ndarray, disp: np.ndarray, *, side_lambda: float,
                      correction_lambda: float, runner=None, ref_modes: bool = True,
                      costs: np.ndarray | None = None):
    """:func:`reprice_maps` without and with ``modes_too`` from one computation (they differ only
    in the modes' final choice): (base, disp, modes, modes repriced)."""
    est = Estimator(luma, struct, list(struct.keys))
    if len(est.cells) == 0:
        z = np.zeros_like(disp)
        return base, disp, z, z
    pen = _mode_penalty(side_lambda, ref_modes)
    pen_delta = SIDE_BITS * correction_lambda

    def total(dmaps):
        f = est.costs_maps(dmaps, runner)
        return f, (f + pen).min(axis=1)

    if costs is None:
        full, cur = total(disp)
    else:                              # (the estimate's own: the same numbers, not evaluated again)
        full = costs
        cur = (full + pen).min(axis=1)
    shared = np.broadcast_to(base[None, :], disp.shape)
    fb, cb = total(np.ascontiguousarray(shared))
    drop = (disp != shared) & (cb <= cur + pen_delta)
    disp = np.where(drop, shared, disp)
    cur, full = np.where(drop, cb, cur), np.where(drop[:, None], fb, full)
    base, disp, cur, full = _regularize(est, total, base, disp, cur, full, side_lambda)
    modes = (full + pen).argmin(axis=1)
    modes_repriced = (full + _mode_penalty(correction_lambda, ref_modes)).argmin(axis=1)
    est.drop_handle()
    return base, disp, modes, modes_repriced
