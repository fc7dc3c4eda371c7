"""Where the key views of a ``tx`` file lie, in which order they are coded, and what each view
is predicted from (the encoder's choice; the decoder reads it from the header).

Key views form a sub-grid: rows round(linspace(0, R−1, n_r)) with n_r = ceil((R−1)/S) + 1
for a spacing S (likewise columns), so views between keys are interpolated, not extrapolated.
The central key is coded alone (intra); the others in order of distance from it (rings), each
from up to 4 already-coded keys at most one key-grid step away. Every other view is
predicted from the 2 or 4 keys around it, blended bilinearly by its position; the views
between the same keys share one map (a "cell").
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .txlayout import MAX_REFS


def key_lines(n: int, spacing: int) -> list[int]:
    """Key rows (or columns) of a grid dimension of n views."""
    if n == 1:
        return [0]
    k = -(-(n - 1) // max(1, spacing)) + 1
    return sorted(set(int(round(x)) for x in np.linspace(0, n - 1, k)))


def _weights64(w: np.ndarray) -> np.ndarray:
    """Non-negative weights → integers summing to 64 (largest remainders)."""
    w = np.asarray(w, np.float64)
    w = w / w.sum() * 64
    out = np.floor(w).astype(np.int64)
    rem = 64 - out.sum()
    for i in np.argsort(-(w - out), kind="stable")[:rem]:
        out[i] += 1
    return out


@dataclass
class Structure:
    """The encoder's plan: see :class:`rlfc.txlayout.TxLayout` for the meaning of the fields;
    ``cell_views`` lists the views of each map."""

    positions: np.ndarray
    keys: list
    refs: np.ndarray
    weights: np.ndarray
    cell: np.ndarray
    cell_views: list
    #: (N0, 4) int64 per-view warps (rlfc.txwarp), or None: the views are taken as rectified
    warp: np.ndarray | None = None


def build(rows: int, cols: int, spacing: int) -> Structure:
    """The key sub-grid, key coding order, references, weights and cells of a rows × cols grid."""
    kr, kc = key_lines(rows, spacing), key_lines(cols, spacing)
    n = rows * cols
    pos = np.stack(np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij"), -1).reshape(n, 2)
    refs = np.full((n, MAX_REFS), -1, np.int64)
    weights = np.zeros((n, MAX_REFS), np.int64)
    cell = np.full(n, -1, np.int64)
    cell_views: list = []
    # key coding order: rings around the central key of the key grid
    kg = [(i, j) for i in range(len(kr)) for j in range(len(kc))]
    ci, cj = (len(kr) - 1) / 2, (len(kc) - 1) / 2
    kg.sort(key=lambda g: (max(abs(g[0] - ci), abs(g[1] - cj)), abs(g[0] - ci) + abs(g[1] - cj), g))
    keys, done = [], []
    for gi, gj in kg:
        v = kr[gi] * cols + kc[gj]
        near = [(abs(gi - a) + abs(gj - b), a, b) for a, b in done if max(abs(gi - a), abs(gj - b)) <= 1]
        near.sort()
        if not near and done:                              # always predict from something coded
            near = sorted((abs(gi - a) + abs(gj - b), a, b) for a, b in done)[:1]
        near = near[:MAX_REFS]
        if near:
            rv = [kr[a] * cols + kc[b] for _, a, b in near]
            d = np.array([np.hypot(kr[a] - kr[gi], kc[b] - kc[gj]) for _, a, b in near])
            refs[v, :len(rv)] = rv
            weights[v, :len(rv)] = _weights64(1.0 / d)
            cell[v] = len(cell_views)
            cell_views.append([v])
        keys.append(v)
        done.append((gi, gj))
    # other views: the keys around them, bilinear weights; one cell per bracket
    brackets: dict = {}
    for r in range(rows):
        for c in range(cols):
            v = r * cols + c
            if r in kr and c in kc:
                continue
            r0 = max(k for k in kr if k <= r)
            r1 = min(k for k in kr if k >= r)
            c0 = max(k for k in kc if k <= c)
            c1 = min(k for k in kc if k >= c)
            rs = [r0] if r0 == r1 else [r0, r1]       # the same order for every view of the cell
            cs = [c0] if c0 == c1 else [c0, c1]
            cand = [(a, b) for a in rs for b in cs]
            w = np.array([(1.0 if r0 == r1 else 1 - abs(a - r) / (r1 - r0)) *
                          (1.0 if c0 == c1 else 1 - abs(b - c) / (c1 - c0)) for a, b in cand])
            rv = [a * cols + b for a, b in cand]
            refs[v, :len(rv)] = rv
            weights[v, :len(rv)] = _weights64(np.maximum(w, 1e-9))
            key = (r0, r1, c0, c1)
            if key not in brackets:
                brackets[key] = len(cell_views)
                cell_views.append([])
            cell[v] = brackets[key]
            cell_views[brackets[key]].append(v)
    return Structure(pos, keys, refs, weights, cell, cell_views)


def build_intra(n: int) -> Structure:
    """Every view a key view coded on its own (captures whose cameras do not form a grid of
    parallel views: posed, 360°): no references, no maps; views keep their order (1 × n)."""
    pos = np.stack([np.zeros(n, np.int64), np.arange(n)], -1)
    return Structure(pos, list(range(n)), np.full((n, MAX_REFS), -1, np.int64), np.zeros((n, MAX_REFS), np.int64),
                     np.full(n, -1, np.int64), [])
