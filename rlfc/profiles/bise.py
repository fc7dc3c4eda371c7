"""Profile ``bise``: the paper's method (Pratapa & Manocha, I3D 2019), kept bit for bit.

Views cluster into a tree (2×2 grid neighbours, or camera distance for posed captures); each
cluster's Representative Key View is the Gaussian-weighted average of its members; the top
key views are coded as images; every level is predicted by its parent's decoded image (the
identity) and corrected by sparse BISE-packed residual blocks. Rate knob: the quantizer step.
"""
from __future__ import annotations

import numpy as np

from formats.codec_api import EncodeOptions

from ..keytree import KeyStrategy
from ..keytree_decode import DecodeStrategy, KeyTreeDecoder
from ..tree import build_tree, filter_level
from .base import Profile
from .keyfamily import encode_keyfamily


class GaussianTree(KeyStrategy, DecodeStrategy):
    """Key views = Gaussian-weighted cluster averages; prediction = the parent itself."""

    profile = "bise"
    index_coding = "raw-u32"

    def build(self, enc, lf, views, params):
        tree = build_tree(lf.rows, lf.cols, lf.positions, params.tree_height, lf.layout)
        keys, cur = [], views
        for lev in range(tree.height):
            cur = filter_level(cur, tree, lev, params.sigma)
            keys.append(cur)
        return tree, keys

    def predict(self, enc, level, nodes, dec_above):
        return dec_above[enc.tree.parents[level][nodes]]

    def predict_blocks(self, st, xp, views, by, bx):
        return st["top_blocks"][st["anc_top"][views], by, bx]

    def predict_one(self, dec, v, by, bx):
        return dec.top_blocks[dec.anc[dec.levels][v], by, bx]

    def predict_nodes(self, dec, level, ids, above, above_ids):
        return above[np.searchsorted(above_ids, dec.tree.parents[level][ids])]


class BiseProfile(Profile):
    id = "bise"
    description = "the paper's key-view tree with BISE-packed sparse residuals"

    def strategy(self, lf=None) -> GaussianTree:
        return GaussianTree()

    def encode(self, lf, options: EncodeOptions, progress=None):
        return encode_keyfamily(lf, options, GaussianTree(), progress)

    def open(self, container, header, cfg, limits=None):
        return KeyTreeDecoder(container, header, cfg, GaussianTree(), limits)


PROFILE = BiseProfile()
