"""The ``tx`` decoder's residual path (:class:`Residuals`, a part of
:class:`rlfc.profiles.tx.TxDecoder`): stored streams parsed (one by one in plain Python, or as
rANS lanes stepping together; a batched call's streams parsed ahead of its chunks in groups:
:class:`ParseAhead`), their coefficients dequantized and inverse-transformed, and added to the
prediction with the planes' clipping."""
from __future__ import annotations

import threading

import numpy as np

from ..transform import ZIGZAG, inverse_float
from ..txparse import concat_parsed, parse_lanes
from ..txparse_one import parse_one
from ..txpredict import TB
from ..txsyntax import MODE_INTRA
from .tx_single import _dequantize_clipped

#: a batched call's coded requests are parsed ahead of its chunks (:meth:`TxDecoder.preparse`)
#: in parses of this many streams, where it has at least PREPARSE_MIN: on epfl_iso_chart_1's
#: 10 862 streams of 20 000 random requests, 1 024 / 2 048 / 4 096 streams a parse took 178 /
#: 141 / 124 ms (a parse's temporaries: 16 / 29 / 62 MB)
PREPARSE_LANES = 4096
PREPARSE_MIN = 1024
#: streams are parsed one by one (plain Python, ~1.5 µs per byte) rather than as numpy lanes
#: stepping together (a step per symbol of the longest stream, whatever the number of lanes) while
#: their bytes sum to less than this many times the longest one's (stop 87, after the lanes' one-type
#: steps: 31 parses of six grids both ways, lanes 1.1-3.6× slower below a ratio of ~20, the two
#: even between 18 and 37, lanes 0.24-0.38× from 48.6 up: BENCHMARKS.md)
ONE_BY_ONE_RATIO = 40


class Residuals:
    """Parsing and residuals; reads the decoder's layout, tables, streams and bounds."""

    def _residual(self, views, parsed):
        """(S, nt, 8, 8, P) int32 residuals of parsed streams of ``views``: the nonzero
        coefficients dequantized where they are, then only the 8×8 blocks that have any are
        inverse-transformed."""
        lay, P, nt = self.lay, self.P, self.nt
        S = views.size
        res = np.zeros((S * nt, 64, P), np.int32)            # (S, nt, 8, 8, P) as it is returned
        idx, q = parsed.index, parsed.values
        if idx.size:
            blk, pos = idx >> 6, idx & 63                                    # (lane, tb, plane), scan position
            plane = blk % P
            deq, raster = self._dequantized(q, lay.step16[np.where(self.is_key[views[blk // (nt * P)]], 0, 1), plane],
                                            plane, pos)
            new = np.ones(blk.size, bool)
            new[1:] = blk[1:] != blk[:-1]
            ub = blk[new]                                                    # blocks with coefficients
            X = np.zeros((ub.size, 64), np.float64)
            X[np.cumsum(new) - 1, raster] = deq
            X = self._inverse_rows(X, ub % P)
            res[ub // P, :, ub % P] = X           # (written planes-last: the sum with the prediction
        return res.reshape(S, nt, TB, TB, P)      # then reads it contiguously, 2x faster than a strided view)

    def _inverse_rows(self, X, plane):
        """(n, 64) float64 dequantized 8×8 blocks (raster rows) of planes ``plane`` (n,) → their
        residuals: the inverse transform of the rows of transformed planes, bypassed ones as
        they are (in place where only some rows are transformed)."""
        bypass = self.lay.bypass
        if not bypass.any():
            return inverse_float(X.reshape(-1, TB, TB)).reshape(-1, 64)
        tr = ~bypass[plane]
        if tr.any():
            X[tr] = inverse_float(X[tr].reshape(-1, TB, TB)).reshape(-1, 64)
        return X

    def _dequantized(self, values, q16, plane, pos):
        """(dequantized coefficients clipped to ±COEF_MAX, each one's raster position in its 8×8
        block: zig-zag for transformed planes, as is for bypassed ones) of nonzero levels
        ``values`` at scan positions ``pos`` of planes ``plane``, steps ``q16`` (1/16)."""
        deq = _dequantize_clipped(values, q16)
        bypass = self.lay.bypass
        return deq, (np.where(bypass[plane], pos, ZIGZAG[pos]) if bypass.any() else ZIGZAG[pos])

    def _parse(self, views, locs):
        """Parse the streams of (view, location) pairs that have one."""
        s, e = self.start[views, locs], self.end[views, locs]
        buf, s2, e2 = self._streams(s, e)
        kind = self.lay.intra[views].astype(np.int64)
        key = self.is_key[views].astype(np.int64)
        return self._parse_streams(buf, s2, e2, self.nt, kind, key)

    def _parse_streams(self, buf, s2, e2, nt: int, kind, key):
        """Parsed of streams ``buf[s2[i]:e2[i]]`` of ``nt`` tbs each (one lane per stream): one
        by one or as lanes, whichever :data:`ONE_BY_ONE_RATIO` says is faster."""
        n = e2 - s2
        if n.size and int(n.sum()) < ONE_BY_ONE_RATIO * max(int(n.max()), 1):
            got = [parse_one(bytes(buf[a:b]), self.tables, nt, self._pcl, int(k), int(y))
                   for a, b, k, y in zip(s2.tolist(), e2.tolist(), kind.tolist(), key.tolist())]
            return got[0] if len(got) == 1 else concat_parsed(got)
        return parse_lanes(buf, s2, e2, self.tables, nt, self.pcs, kind, key, self.container.name)

    def _add_residual(self, pred, res, modes):
        """Clipped prediction (intra tbs: the flat value) + residual, (S, nt, 8, 8, P) int32.
        Predictions need no clipping: they blend clipped key views with weights summing to 64."""
        base = np.add(pred, res, dtype=np.int32)
        intra = modes == MODE_INTRA                                   # (S, nt): flat value + residual
        if intra.any():
            base[intra] = (res[intra] + self.flat.astype(np.int32)).astype(np.int32)
        # clipped per plane with the bounds tiled over a tb (8·8·P): numpy's inner loop then runs
        # 64·P samples, not P (the (P,) bounds broadcast against the last axis: 7x slower, measured)
        flat = base.reshape(-1, TB * TB * self.P)
        np.minimum(np.maximum(flat, self.lo_tb, out=flat), self.hi_tb, out=flat)   # ufuncs: np.clip costs µs
        return base

    def preparse(self, views, by, bx, level):
        """For a batched call (``views``, ``by``, ``bx`` in the order its chunks take them): its
        coded requests of views with references, to be parsed :data:`PREPARSE_LANES` streams at
        a time as its chunks first need them (:class:`ParseAhead`). The rANS lanes of a parse
        step together, one step per symbol of its longest stream, so fewer and fuller parses
        cost less than one per chunk (BENCHMARKS.md). None where there are too few to gain (or
        at a level without residuals)."""
        if level != 0:
            return None
        loc = by * self.nbx + bx
        have = np.flatnonzero(~self.is_key[views] & self.coded[views, loc])
        if have.size < PREPARSE_MIN:
            return None
        return ParseAhead(self, views[have], loc[have], have, views.size)


class ParseAhead:
    """The coded requests of one batched call (streams of views with references), parsed in
    groups of :data:`PREPARSE_LANES` streams, each group once, by the first chunk that needs it
    (others that need it wait; chunks on other threads predict meanwhile).

    Args:
        core: the :class:`TxDecoder`; views, locs: (S,) the coded requests' views and block
            locations, in the call's order; at: (S,) their places among the call's M requests.
    """

    def __init__(self, core, views, locs, at, M: int):
        self.core, self.views, self.locs = core, views, locs
        self.lane = np.full(M, -1, np.int64)
        self.lane[at] = np.arange(at.size)
        n = -(-at.size // PREPARSE_LANES)
        self.parsed: list = [None] * n                 # per group: (Parsed, its lane bounds)
        self.locks = [threading.Lock() for _ in range(n)]

    def _group(self, g: int) -> tuple:
        with self.locks[g]:
            if self.parsed[g] is None:
                a, b = g * PREPARSE_LANES, (g + 1) * PREPARSE_LANES
                p = self.core._parse(self.views[a:b], self.locs[a:b])
                self.parsed[g] = (p, p.lane_bounds())
            return self.parsed[g]

    def chunk(self, idx: np.ndarray) -> tuple:
        """(places within ``idx`` of its coded requests, their Parsed) for the call's requests
        ``idx`` (ascending, as the decoder's chunks take them; else those streams are parsed
        on their own)."""
        lane = self.lane[idx]
        have = np.flatnonzero(lane >= 0)
        lane = lane[have]
        if not lane.size:
            return have, None
        if lane.size > 1 and (np.diff(lane) <= 0).any():      # (not in the call's order: parsed as they are)
            return have, self.core._parse(self.views[lane], self.locs[lane])
        parts = []
        for g in range(int(lane[0]) // PREPARSE_LANES, int(lane[-1]) // PREPARSE_LANES + 1):
            p, bounds = self._group(g)
            sel = lane[(lane >= g * PREPARSE_LANES) & (lane < (g + 1) * PREPARSE_LANES)]
            parts.append(p.take(sel - g * PREPARSE_LANES, bounds))
        return have, parts[0] if len(parts) == 1 else concat_parsed(parts)
