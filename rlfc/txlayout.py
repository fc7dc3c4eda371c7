"""The ``tx`` profile's header (``config.tx``): one typed schema for encoder and decoder.

Views (flat index v = row·cols + col) have integer grid positions, up to 4 reference views
(always key views) with blend weights summing to 64, and a map (disparity + prediction mode
per 8×8 block) shared by the views of one cell. Key views are coded in ``keys`` order, each
from references earlier in that order (or, with none, from its thumbnail: an intra view), one
stream per block row (or ``key_split`` streams side by side), so a decoder can decode them by
block rows when a request first needs them (the rows a prediction samples, and the rows those
rows are predicted from); every other view is decoded block by block on demand from key views
alone, so a block request needs the key-view rows around it and at most one stored stream.
"""
from __future__ import annotations

import zlib
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from formats.errors import FormatError
from formats.schema import Fields

from .txwarp import check_params

MAX_REFS = 4
VERSION = 2          # 2: rANS tables built in integers (1: float arithmetic)
SPLIT_VERSION = 3    # 3: as 2, with key-view block rows coded as ``key_split`` streams each
WP_VERSION = 4       # 4: as 3 (``key_split`` >= 1), with a weighted prediction per view and plane
WARP_VERSION = 5     # 5: as 4, with a warp per view (rlfc.txwarp: rigs that are not rectified)
ALPHA_VERSION = 6    # 6: as 5, with views' alpha planes exact after their JPEG 2000 colour (``key_alpha``)
#: a weighted prediction's gain, in 1/64 (64: the identity), lies within these
WP_GAIN = (32, 96)


def weighted_planes(wp: np.ndarray) -> np.ndarray:
    """(…, P) bool: the planes whose weighted prediction (``wp`` (…, P, 2) gains and offsets) is
    not the identity (gain 64, offset 0)."""
    return (wp[..., 0] != 64) | (wp[..., 1] != 0)


def weighted_views(wp: np.ndarray) -> np.ndarray:
    """(N,) bool: the views whose weighted prediction (``wp`` (N, P, 2)) is not the identity on
    some plane."""
    return weighted_planes(wp).any(axis=-1)


@dataclass(frozen=True)
class TxLayout:
    """Attributes:
        positions: (N0, 2) int grid (row, col) of each view.
        keys: key views in decode order.
        refs: (N0, 4) reference views (−1 = none); weights: (N0, 4) ints (sum 64 with refs).
        cell: (N0,) map of each view (−1 for intra views).
        n_maps: maps in ``tx.maps``.
        step16: (2, P) quantizer steps in 1/16 units, row 0 for key views, row 1 for the others.
        bypass: (P,) planes coded without transform (alpha; every plane when lossless).
        thumb_step16: quantizer step of intra views' thumbnails, 1/16 units.
        intra_codec: how intra key views are coded: "tx" (thumbnail + transform) or "j2k"
            (a JPEG 2000 codestream in ``tx.keyimg``, lengths in ``key_images``).
        key_images: with intra_codec "j2k", one entry per intra key view in key order: the byte
            length of its JPEG 2000 codestream, or 0 when that view is transform-coded (its
            rows are in ``tx.blocks`` like any key's).
        key_split: streams per key-view block row (a divisor of the blocks per row; 1 = one
            stream per row). Each stream codes nbx / key_split consecutive blocks of the row, so
            a decoder parses a key row as that many independent rANS lanes.
        version: 2 (1: the first files, whose rANS tables were built in float arithmetic; 3: as
            2 with ``key_split`` > 1; 4: weighted prediction, ``key_split`` >= 1; 5: as 4, with
            a warp per view; 6: as 5, with ``key_alpha``).
        wp: (N0, P, 2) int64 or None (before version 4): per view and plane, the gain g (1/64)
            and offset o of its weighted prediction: a predicted view's blended prediction p
            becomes clip(((p·g + 32) >> 6) + o) to the plane's range, before its residual
            (intra views: the identity, g = 64, o = 0).
        warp: (N0, 4) int64 or None (before version 5): per view, the warp (a, b, cx, cy) of
            :mod:`rlfc.txwarp` its predictions sample their references with.
        key_alpha: version 6 (views with alpha, intra_codec "j2k"), one entry per ``key_images``
            entry: the byte length of the alpha stream (:func:`rlfc.topcodec.alpha_stream`) that
            ends that image entry, its JPEG 2000 codestream before it holding the colour
            channels only (0 where the entry is 0). Before version 6 a JPEG 2000 entry is one
            codestream of every channel.
    """

    positions: np.ndarray
    keys: tuple
    refs: np.ndarray
    weights: np.ndarray
    cell: np.ndarray
    n_maps: int
    step16: np.ndarray
    bypass: np.ndarray
    thumb_step16: int
    intra_codec: str = "tx"
    key_images: tuple = ()
    version: int = VERSION
    key_split: int = 1
    wp: np.ndarray | None = None
    warp: np.ndarray | None = None
    key_alpha: tuple = ()

    @property
    def n_views(self) -> int:
        return len(self.cell)

    @property
    def is_key(self) -> np.ndarray:
        k = np.zeros(self.n_views, bool)
        k[list(self.keys)] = True
        return k

    @cached_property
    def intra(self) -> np.ndarray:
        """(N0,) views with no references (read-only; computed once: an open of a posed capture
        asked for it 400 times)."""
        a = (self.refs < 0).all(axis=1)
        a.flags.writeable = False
        return a

    def to_config(self) -> dict:
        """The JSON part (``config.tx``); the per-view tables go to :meth:`to_bytes`."""
        return {"version": int(self.version), "keys": list(map(int, self.keys)), "n_maps": int(self.n_maps),
                "step16": self.step16.tolist(), "bypass": [bool(b) for b in self.bypass],
                "thumb_step16": int(self.thumb_step16), "intra_codec": self.intra_codec,
                "key_images": list(map(int, self.key_images))} | (
                    {"key_split": int(self.key_split)} if self.version >= SPLIT_VERSION else {}) | (
                    {"key_alpha": list(map(int, self.key_alpha))} if self.version >= ALPHA_VERSION else {})

    def to_bytes(self) -> bytes:
        """Section ``tx.layout``: zlib of zig-zag varints: positions (N0×2), refs (N0×4),
        weights (N0×4), cell (N0), view-major; version 4: then the weighted predictions' gains
        less 64 (N0×P) and offsets (N0×P); version 5: then each view's warp (N0×4)."""
        from .txsections import varints

        parts = [self.positions.reshape(-1), self.refs.reshape(-1), self.weights.reshape(-1), self.cell]
        if self.wp is not None:        # (version 4: then each view's gains − 64 and offsets, plane by plane)
            parts += [(self.wp[..., 0] - 64).reshape(-1), self.wp[..., 1].reshape(-1)]
        if self.warp is not None:      # (version 5: then each view's warp a, b, cx, cy)
            parts += [self.warp.reshape(-1)]
        return zlib.compress(varints(np.concatenate(parts)), 9)

    @staticmethod
    def read(f: Fields, data, n_views: int, planes: int, name: str = "") -> "TxLayout":
        """Validate ``config.tx`` and section ``tx.layout`` for a light field of ``n_views`` views
        and ``planes`` planes."""
        from .txsections import MAX_VARINT_BYTES, inflate, unvarints

        where = f.where
        version = f.int("version", choices=(1, VERSION, SPLIT_VERSION, WP_VERSION, WARP_VERSION, ALPHA_VERSION))
        if version >= ALPHA_VERSION and planes not in (2, 4):
            raise FormatError(f"{where}: version {ALPHA_VERSION} (alpha streams) needs views with alpha")
        count = n_views * (2 + 2 * MAX_REFS + 1) + (2 * n_views * planes if version >= WP_VERSION else 0) + \
            (4 * n_views if version >= WARP_VERSION else 0)
        what = f"{name}: section 'tx.layout'"
        v = unvarints(inflate(data, count * MAX_VARINT_BYTES, what), count, what)
        positions = v[:2 * n_views].reshape(n_views, 2)
        refs = v[2 * n_views:(2 + MAX_REFS) * n_views].reshape(n_views, MAX_REFS)
        weights = v[(2 + MAX_REFS) * n_views:(2 + 2 * MAX_REFS) * n_views].reshape(n_views, MAX_REFS)
        cell = v[(2 + 2 * MAX_REFS) * n_views:(2 + 2 * MAX_REFS + 1) * n_views]
        wp = None
        if version >= WP_VERSION:
            rest = v[(2 + 2 * MAX_REFS + 1) * n_views:]
            wp = np.stack([rest[:n_views * planes] + 64, rest[n_views * planes:2 * n_views * planes]],
                          axis=-1).reshape(n_views, planes, 2)
        warp = v[count - 4 * n_views:].reshape(n_views, 4) if version >= WARP_VERSION else None
        for arr, lo, hi, what_ in ((positions, -(1 << 16), 1 << 16, "positions"), (refs, -1, n_views - 1, "refs"),
                                   (weights, 0, 64, "weights"), (cell, -1, n_views, "cell")):
            if arr.size and (arr.min() < lo or arr.max() > hi):
                raise FormatError(f"{where}: {what_} out of range [{lo}, {hi}]")
        n_maps = f.int("n_maps", 0, n_views)
        keys = f.int_list("keys", min_len=1, max_len=n_views, lo=0, hi=n_views - 1)
        srows = f.list("step16", max_len=2)
        if len(srows) != 2:
            raise FormatError(f"{where}: step16 must hold 2 rows (key views, other views)")
        step16 = np.asarray([Fields({"r": r}, f"{where}.step16").int_list("r", length=planes, lo=16, hi=1 << 24)
                             for r in srows], dtype=np.int64)
        bp = f.list("bypass", max_len=planes)
        if len(bp) != planes or not all(isinstance(b, bool) for b in bp):
            raise FormatError(f"{where}: bypass must be {planes} booleans")
        thumb = f.int("thumb_step16", 16, 1 << 24)
        intra_codec = f.str("intra_codec", choices=("tx", "j2k"))
        key_images = f.int_list("key_images", max_len=n_views, lo=0, hi=1 << 30)
        key_split = f.int("key_split", 1 if version >= WP_VERSION else 2, 1 << 16) if version >= SPLIT_VERSION else 1
        key_alpha = tuple(f.int_list("key_alpha", max_len=n_views, lo=0, hi=1 << 30)) if version >= ALPHA_VERSION else ()
        lay = TxLayout(positions, tuple(keys), refs, weights, cell, n_maps, step16, np.asarray(bp), thumb,
                       intra_codec, tuple(key_images), version, key_split, wp, warp, key_alpha)
        lay.check(where)
        return lay

    @property
    def intra_keys(self) -> list:
        """The intra key views (no references), in key order: one ``key_images`` (and
        ``key_alpha``) entry each."""
        return [k for k in self.keys if self.intra[k]]

    @property
    def image_of(self) -> dict:
        """{intra key view: JPEG 2000 byte length} for the keys coded as JPEG 2000 (j2k files)."""
        if self.intra_codec != "j2k":
            return {}
        ik = self.intra_keys
        return {k: n for k, n in zip(ik, self.key_images) if n > 0}

    @property
    def alpha_of(self) -> dict:
        """{JPEG 2000 intra key view: byte length of the alpha stream ending its entry} (version
        6; empty before)."""
        if self.version < ALPHA_VERSION:
            return {}
        ik = self.intra_keys
        return {k: a for k, n, a in zip(ik, self.key_images, self.key_alpha) if n > 0}

    @property
    def coded_keys(self) -> list:
        """Key views coded as row streams (all but the JPEG 2000 intra views), in key order."""
        img = self.image_of
        return [k for k in self.keys if k not in img]

    def check(self, where: str) -> None:
        """Structural rules: references are key views decoded earlier (for keys) or key views
        (for the others); weights sum to 64 over present references; intra views are keys;
        one JPEG 2000 length per intra key when they are JPEG 2000."""
        n = self.n_views
        if self.version < WP_VERSION and (self.version >= SPLIT_VERSION) != (self.key_split > 1):
            raise FormatError(f"{where}: key_split {self.key_split} needs version {SPLIT_VERSION} (and only it)")
        if (self.wp is not None) != (self.version >= WP_VERSION):
            raise FormatError(f"{where}: weighted prediction needs version {WP_VERSION} or later (and only they)")
        if (self.warp is not None) != (self.version >= WARP_VERSION):
            raise FormatError(f"{where}: per-view warps need version {WARP_VERSION} or later (and only they)")
        if self.warp is not None:
            check_params(self.warp, where)
        if self.wp is not None:
            g, o = self.wp[..., 0], self.wp[..., 1]
            if g.min() < WP_GAIN[0] or g.max() > WP_GAIN[1]:
                raise FormatError(f"{where}: a weighted prediction's gain is outside {WP_GAIN[0]}..{WP_GAIN[1]} (1/64)")
            if np.abs(o).max() > 1 << 18:
                raise FormatError(f"{where}: a weighted prediction's offset is out of range")
            if weighted_views(self.wp)[self.intra].any():
                raise FormatError(f"{where}: an intra view has a weighted prediction")
        want = int(self.intra[list(self.keys)].sum()) if self.intra_codec == "j2k" else 0
        if len(self.key_images) != want:
            raise FormatError(f"{where}: key_images lists {len(self.key_images)} images, expected {want}")
        if self.version >= ALPHA_VERSION:
            if self.intra_codec != "j2k" or not any(self.key_images):
                raise FormatError(f"{where}: version {ALPHA_VERSION} (alpha streams) needs JPEG 2000 key views")
            if len(self.key_alpha) != len(self.key_images):
                raise FormatError(f"{where}: key_alpha lists {len(self.key_alpha)} streams, expected {len(self.key_images)}")
            for size, a in zip(self.key_images, self.key_alpha):
                if (size == 0 and a != 0) or (size > 0 and not 0 < a < size):
                    raise FormatError(f"{where}: an alpha stream of {a} bytes does not fit its image entry of {size}")
        elif self.key_alpha:
            raise FormatError(f"{where}: key_alpha needs version {ALPHA_VERSION}")
        if len(set(self.keys)) != len(self.keys):
            raise FormatError(f"{where}: a key view is listed twice")
        order = np.full(n, -1)
        order[list(self.keys)] = np.arange(len(self.keys))
        has = self.refs >= 0
        if ((self.weights > 0) & ~has).any():
            raise FormatError(f"{where}: a weight is given to a missing reference")
        wsum = self.weights.sum(axis=1)
        if ((wsum != 64) & has.any(axis=1)).any():
            raise FormatError(f"{where}: blend weights must sum to 64")
        for v in range(n):
            r = self.refs[v][has[v]]
            if len(set(r.tolist())) != r.size:
                raise FormatError(f"{where}: view {v} lists a reference twice")
            if r.size == 0:
                if order[v] < 0:
                    raise FormatError(f"{where}: view {v} has no references but is not a key view")
                if self.cell[v] != -1:
                    raise FormatError(f"{where}: intra view {v} must have cell -1")
                continue
            if (order[r] < 0).any():
                raise FormatError(f"{where}: view {v} references a view that is not a key view")
            if order[v] >= 0 and (order[r] >= order[v]).any():
                raise FormatError(f"{where}: key view {v} references a key decoded after it")
            if not 0 <= self.cell[v] < self.n_maps:
                raise FormatError(f"{where}: view {v} has map {self.cell[v]} of {self.n_maps}")
