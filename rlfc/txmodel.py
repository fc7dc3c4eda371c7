"""The entropy model the ``tx`` encoder decides with: code lengths from symbol counts
(:class:`Model`), a first model before any statistics (:func:`default_counts`), and the bits of
coefficient levels under a model."""
from __future__ import annotations

import numpy as np

from .txsyntax import ALPHABET, BAND, ESC, MODE_INTRA, MODE_RES, N_CTX, ctx_esc, ctx_last, ctx_mag, ctx_mode


def default_counts() -> np.ndarray:
    """A plausible first model (before any statistics): mostly skips, small magnitudes."""
    c = np.ones((N_CTX, ALPHABET))
    for kind in range(2):
        for prev in range(4):
            c[ctx_mode(kind, prev), :3] = [60, 30, 3]
    for pc in range(3):
        for mode in (MODE_RES, MODE_INTRA):
            for key in range(2):
                c[ctx_last(pc, mode, key), :65] = np.r_[80, 60 * np.exp(-np.arange(64) / 8)] + 0.1
        for band in range(6):
            for key in range(2):
                for nb in range(4):
                    c[ctx_mag(pc, band, key, nb), :16] = 1000 * np.exp(-np.arange(16) * (1.0 + 0.2 * band)) + 0.1
        c[ctx_esc(pc), :24] = 2.0 ** -np.arange(24) * 1000 + 0.01
    return c


class Model:
    """Code lengths (bits) for decisions, from (N_CTX, ALPHABET) counts (add-one smoothed)."""

    def __init__(self, counts: np.ndarray):
        self.counts = counts                  # (kept: models between two steps interpolate them)
        c = counts + 0.5
        bits = -np.log2(c / c.sum(axis=1, keepdims=True))
        self.mode = np.zeros((2, 3))
        for kind in range(2):
            rows = [ctx_mode(kind, p) for p in range(4)]
            m = c[rows, :3].sum(0)
            self.mode[kind] = -np.log2(m / m.sum())
        self.last = np.zeros((3, 2, 2, 65))
        self.mag = np.zeros((3, 6, 2, 16))
        self.first = np.zeros((3, 6, 2, 16))
        self.esc = np.zeros((3, 24))
        for pc in range(3):
            for mi, mode in enumerate((MODE_RES, MODE_INTRA)):
                for key in range(2):
                    self.last[pc, mi, key] = bits[ctx_last(pc, mode, key), :65]
            for band in range(6):
                for key in range(2):
                    rows = [ctx_mag(pc, band, key, nb) for nb in (1, 2, 3)]
                    m = c[rows, :16].sum(0)
                    self.mag[pc, band, key] = -np.log2(m / m.sum())
                    self.first[pc, band, key] = bits[ctx_mag(pc, band, key, 0), :16]
            self.esc[pc] = bits[ctx_esc(pc), :24]
        self._pos = {}

    def pos_bits(self, pc: int, key: int) -> np.ndarray:
        """(64·16,) magnitude-symbol bits by scan position and symbol (flat), cached."""
        k = (pc, key)
        if k not in self._pos:
            self._pos[k] = np.ascontiguousarray(self.mag[pc, BAND, key]).reshape(-1)
        return self._pos[k]

    def zero_bits(self, pc: int, key: int) -> tuple[np.ndarray, np.ndarray]:
        """(bits of a coded 0 at each scan position (64,) float32, their prefix sums (65,)
        float64), cached: the quantizer's costs."""
        k = (pc, key, 0)
        if k not in self._pos:
            b = self.pos_bits(pc, key)[::16]
            self._pos[k] = (b.astype(np.float32), np.concatenate([[0.0], np.cumsum(b)]))
        return self._pos[k]


def _level_bits(model: Model, l: np.ndarray, pc: int, key: int) -> np.ndarray:
    """Bits of coding magnitudes l (>= 0, (T, 64) in scan order), not the last one: symbol,
    sign, escape bucket and suffix."""
    return _level_bits_at(model, l, np.arange(64)[None, :], pc, key)


def _level_bits_at(model: Model, l: np.ndarray, col: np.ndarray, pc: int, key: int) -> np.ndarray:
    """:func:`_level_bits` of magnitudes ``l`` (>= 0) at scan positions ``col`` (arrays that
    broadcast together: (n,) and (n,), or (T, 64) and (1, 64))."""
    tab = model.pos_bits(pc, key)                           # (64·16,) flat: position·16 + symbol
    b = tab.take(col * 16 + np.minimum(l, ESC)) + (l > 0)
    big = l >= ESC
    if big.any():
        r = l[big] - ESC
        k = np.floor(np.log2(r + 1.0)).astype(np.int64)
        b[big] += model.esc[pc, np.minimum(k, 23)] + k
    return b
