"""The key-view tree: clustering views by camera position and Gaussian-weighted filtering
into Representative Key Views (RKV).

Level 0 holds the views; level l+1 holds one RKV per cluster of level-l nodes; the top level
(the tree height H) is coded as images. Grids cluster 2×2 neighbours; irregular captures
cluster by camera distance (deterministic k-means, about 4 nodes a cluster).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from formats.errors import ParameterError


@dataclass(frozen=True)
class Tree:
    """parents[l]: (N_l,) index of each level-l node's parent in level l+1, for l = 0..H-1.

    sizes: (N_0, ..., N_H) nodes per level. positions[l]: (N_l, 3) node camera centres.
    """

    parents: tuple
    sizes: tuple
    positions: tuple

    @property
    def height(self) -> int:
        return len(self.parents)

    def ancestors(self) -> np.ndarray:
        """(H+1, N_0) ancestor index of every view at every level (row 0 = the view itself)."""
        anc = [np.arange(self.sizes[0])]
        for p in self.parents:
            anc.append(np.asarray(p)[anc[-1]])
        return np.stack(anc)

    def to_config(self) -> dict:
        return {"parents": [np.asarray(p).tolist() for p in self.parents], "sizes": list(self.sizes)}


def _kmeans(pos: np.ndarray, k: int, iters: int = 20) -> np.ndarray:
    """Deterministic k-means (farthest-point init) → (N,) labels 0..k-1, every label used."""
    n = len(pos)
    centres = [int(np.argmin(np.linalg.norm(pos - pos.mean(0), axis=1)))]
    d = np.linalg.norm(pos - pos[centres[0]], axis=1)
    for _ in range(1, k):
        centres.append(int(np.argmax(d)))
        d = np.minimum(d, np.linalg.norm(pos - pos[centres[-1]], axis=1))
    c = pos[centres].copy()
    labels = np.zeros(n, dtype=np.int64)
    for _ in range(iters):
        labels = np.argmin(((pos[:, None, :] - c[None]) ** 2).sum(-1), axis=1)
        for j in range(k):
            if (labels == j).any():
                c[j] = pos[labels == j].mean(0)
    used = np.unique(labels)
    return np.searchsorted(used, labels)


def build_tree(rows: int, cols: int, positions: np.ndarray, height: int, layout: str = "grid") -> Tree:
    """Build the clustering tree.

    Args:
        rows, cols: the view grid (1 × N for unordered captures).
        positions: (rows, cols, 3) camera centres.
        height: requested tree height; capped where a level would have one node more than once.
        layout: "grid" clusters 2×2 grid neighbours, anything else clusters by distance.
    """
    if height < 0:
        raise ParameterError(f"tree height must be >= 0, got {height}")
    pos = np.asarray(positions, dtype=np.float64).reshape(rows * cols, 3)
    parents, sizes, poss = [], [rows * cols], [pos]
    r, c = rows, cols
    grid = layout == "grid"
    for _ in range(height):
        n = sizes[-1]
        if n == 1:
            break
        if grid:
            rr, cc = np.meshgrid(np.arange(r), np.arange(c), indexing="ij")
            nr, nc = -(-r // 2), -(-c // 2)
            par = ((rr // 2) * nc + (cc // 2)).reshape(-1)
            r, c = nr, nc
        else:
            par = _kmeans(poss[-1], max(1, -(-n // 4)))
        k = int(par.max()) + 1
        cen = np.zeros((k, 3))
        np.add.at(cen, par, poss[-1])
        cen /= np.bincount(par, minlength=k)[:, None]
        parents.append(par.astype(np.int64))
        sizes.append(k)
        poss.append(cen)
    return Tree(tuple(parents), tuple(sizes), tuple(poss))


def cluster_weights(tree: Tree, level: int, sigma: float) -> np.ndarray:
    """(N_level,) Gaussian weights exp(-d²/2σ²) of level-``level`` nodes, d = distance to their
    cluster centre in units of the level's median nearest-neighbour spacing (σ likewise)."""
    pos = tree.positions[level]
    par = tree.parents[level]
    cen = tree.positions[level + 1][par]
    d = np.linalg.norm(pos - cen, axis=1)
    if len(pos) > 1:
        dd = np.linalg.norm(pos[:, None] - pos[None], axis=-1)
        np.fill_diagonal(dd, np.inf)
        spacing = float(np.median(dd.min(1)))
    else:
        spacing = 1.0
    spacing = spacing if spacing > 0 else 1.0
    return np.exp(-(d / spacing) ** 2 / (2.0 * sigma ** 2))


def filter_level(imgs: np.ndarray, tree: Tree, level: int, sigma: float) -> np.ndarray:
    """RKVs of level+1: Gaussian-weighted average of each cluster of level-``level`` images.

    Args:
        imgs: (N_level, H, W, C) uint8/uint16 images.

    Returns:
        (N_level+1, H, W, C) images of the same dtype (rounded).
    """
    par = tree.parents[level]
    w = cluster_weights(tree, level, sigma)
    order = np.argsort(par, kind="stable")
    sp = par[order]
    starts = np.flatnonzero(np.r_[True, sp[1:] != sp[:-1]])
    wsum = np.add.reduceat(w[order], starts)
    out = np.empty((len(starts),) + imgs.shape[1:], dtype=imgs.dtype)
    for j, (a, b) in enumerate(zip(starts, np.r_[starts[1:], len(order)])):  # one pass per RKV (tens)
        acc = np.tensordot(w[order[a:b]] / wsum[j], imgs[order[a:b]].astype(np.float32), axes=1)
        out[j] = np.clip(np.rint(acc), 0, np.iinfo(imgs.dtype).max).astype(imgs.dtype)
    return out
