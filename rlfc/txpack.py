"""The ``tx`` encoder's symbols and file (:class:`FilePacker`, a part of
:class:`rlfc.txencode.TxEncoder`): every stream's symbols part by part, the entropy tables from
their counts, the key rows' split into streams, and the sections of the ``.lfc`` file."""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .txlayout import ALPHA_VERSION, SPLIT_VERSION, VERSION, WARP_VERSION, WP_VERSION, TxLayout, weighted_views
from .txmaps import pack_maps
from .txmodel import Model, default_counts
from .txparams import params_info
from .txsections import pack_index, pack_thumbs, stream_order
from .txsyntax import (PACK_CELLS, block_symbols, count_symbols, pack_streams, quantize_counts, tables_from_quantized,
                       tables_to_bytes)

if TYPE_CHECKING:
    from .txencode import ViewCode

#: auto key_split: the shortest estimated key-row stream worth its own state and index entry
KEY_SEGMENT_BYTES = 256
#: auto key_split: a decoder parses the streams of many key rows as lanes in lockstep, one step
#: per symbol of the longest (~30 µs a numpy step on the 2-core box, whatever the lanes), so rows
#: that KEY_SEGMENT_BYTES splits are split further until no stream holds more magnitude symbols
#: than this (a first frame's key rows then parse in ≲ 60 ms), while streams keep at least
#: KEY_MIN_SEGMENT_BYTES. Grids only, and rows that are split already: lytro_dino_2067's rows
#: of one stream at 40 dB split in 3 cost 1.2% and made its first frame slower (42 → 72 ms: lanes
#: instead of one by one); mitsuba_objects_360's (every view intra, a request reads one view's
#: rows) 4 → 8 cost 0.8% and decoded no faster.
KEY_LANE_SYMBOLS = 2048
KEY_MIN_SEGMENT_BYTES = 64
PAD = 8                   # zero bytes after the last stream (the decoder's reads past a stream stay inside)


class FilePacker:
    """A run's streams and file."""

    SYMBOL_CHUNK = 1024        # random-access blocks turned into symbols at a time (bounds memory)

    def coded_blocks(self, res: dict) -> np.ndarray:
        """(n0, nloc) bool: the random-access blocks of the views that are not key views that
        have a stream."""
        coded = np.zeros((self.n0, self.nby * self.nbx), bool)
        for v, c in enumerate(res["codes"]):
            if not self.is_key[v] and c is not None:
                coded[v] = c.coded
        return coded

    def symbol_parts(self, res: dict, counts_only: bool = False, split: int = 1):
        """Every stream's symbols, in ``tx.blocks`` order (the key views' rows, then the other
        views' coded blocks, location-major), a part at a time: yields (lanes in the part,
        symbols of :func:`rlfc.txsyntax.block_symbols` with lanes numbered within the part).
        Parts are one key view, or up to SYMBOL_CHUNK blocks of the others, so that symbols
        of a high-rate light field never all exist at once. ``counts_only``: each part's symbol
        counts instead (no ordering, no raw bits). ``split``: streams per key row."""
        tbi = self._ra_tbs()
        for k in self.coded_keys(res):                   # key rows: split lanes of nbx·nt/split tbs each
            yield self.nby * split, self._key_symbols(k, res["codes"][k], counts_only, split)
        sv, sl = stream_order(self.coded_blocks(res))     # location-major, views ascending
        for a in range(0, sv.size, self.SYMBOL_CHUNK):
            v_, l_ = sv[a:a + self.SYMBOL_CHUNK], sl[a:a + self.SYMBOL_CHUNK]
            modes = np.zeros((v_.size, self.nt), np.int64)
            levels = np.zeros((v_.size, self.nt, self.P, 64), np.int64)
            for v in np.unique(v_).tolist():
                i = np.flatnonzero(v_ == v)
                c = res["codes"][v]
                modes[i] = c.modes[tbi[l_[i]]]
                levels[i] = c.levels(tbi[l_[i]].reshape(-1)).reshape(i.size, self.nt, self.P, 64)
            yield v_.size, block_symbols(modes, levels, self.intra[v_].astype(np.int64), np.zeros(v_.size, np.int64),
                                         self.pcs, counts_only)

    def _key_symbols(self, k: int, c: ViewCode, counts_only: bool = False, split: int = 1):
        """The symbols of key view k coded as ``c``: ``split`` lanes per block row (nbx·nt/split
        tbs each, the row's blocks in order), as :func:`rlfc.txsyntax.block_symbols` gives them
        (``counts_only``: their counts)."""
        tbi = self._ra_tbs()
        n, seg = self.nby * split, self.nbx * self.nt // split
        modes = c.modes[tbi].astype(np.int64).reshape(n, seg)
        levels = c.levels(tbi.reshape(-1)).reshape(n, seg, self.P, 64)
        return block_symbols(modes, levels, np.full(n, int(self.intra[k])), np.ones(n, np.int64),
                             self.pcs, counts_only)

    def key_split(self, res: dict) -> int:
        """Streams per key-view block row for the file of a run: ``TxParams.key_split`` (the
        largest divisor of the blocks per row not above it), or, when 0, the most streams whose
        estimated length stays at least :data:`KEY_SEGMENT_BYTES` (each costs a 3-byte state and
        an index entry; a decoder parses a row's streams as parallel lanes). Where that splits
        the rows of a grid, more while the longest stream would hold over
        :data:`KEY_LANE_SYMBOLS` magnitude symbols (the decoder's steps), in streams of at least
        :data:`KEY_MIN_SEGMENT_BYTES`."""
        divs = [d for d in range(1, self.nbx + 1) if self.nbx % d == 0]
        if self.p.key_split:
            return max(d for d in divs if d <= self.p.key_split)
        ck = self.coded_keys(res)
        if not ck:
            return 1
        row_bytes = sum(res["codes"][k].bits for k in ck) / 8 / (len(ck) * self.nby)
        split = max(d for d in divs if d == 1 or row_bytes / d >= KEY_SEGMENT_BYTES)
        if split == 1 or self.all_intra:    # (see KEY_LANE_SYMBOLS)
            return split
        blocks = np.stack([self._block_symbols(res["codes"][k]) for k in ck])      # (keys, nby, nbx)
        for d in divs:
            if d <= split:
                continue
            if (blocks.reshape(len(ck), self.nby, split, -1).sum(3).max() <= KEY_LANE_SYMBOLS
                    or row_bytes / d < KEY_MIN_SEGMENT_BYTES):
                break
            split = d
        return split

    def _block_symbols(self, c: ViewCode) -> np.ndarray:
        """(nby, nbx) magnitude symbols of each random-access block of a coded view: the tbs'
        last positions (1 + the last nonzero level's scan index), summed over planes and tbs."""
        per_tb = np.zeros(self.nby8 * self.nbx8, np.int64)
        if c.tbs.size:
            nz = c.lv != 0
            per_tb[c.tbs] = np.where(nz.any(-1), 64 - np.argmax(nz[..., ::-1], -1), 0).sum(1)
        return per_tb[self._ra_tbs()].sum(1).reshape(self.nby, self.nbx)

    def counts_of(self, res: dict, split: int = 1) -> np.ndarray:
        """(N_CTX, ALPHABET) symbol counts of a run (part by part; ``split`` streams per key row)."""
        total = None
        for _, c in self.symbol_parts(res, counts_only=True, split=split):
            total = c if total is None else total + c
        return total if total is not None else count_symbols(np.zeros(0, np.int64), np.zeros(0, np.int64))

    def coded_keys(self, res: dict) -> list:
        """Key views coded as row streams (not JPEG 2000), in key order."""
        return [k for k in self.s.keys if k not in res["keyimg"] and res["codes"][k] is not None]

    def structure_of(self, res: dict):
        """(keys, refs, weights, cell, intra) of a run: the plan with the views it coded alone
        as JPEG 2000 (``res["promoted"]``) made intra keys (no references, no map); promoted
        views that were not keys come after the planned keys, in view order."""
        promoted = [int(v) for v in res.get("promoted", ())]
        refs, weights, cell = self.s.refs.copy(), self.s.weights.copy(), self.s.cell.copy()
        refs[promoted], weights[promoted], cell[promoted] = -1, 0, -1
        keys = list(self.s.keys) + sorted(v for v in promoted if not self.is_key[v])
        return keys, refs, weights, cell, (refs < 0).all(axis=1)

    def model_of(self, res: dict) -> Model:
        """The entropy model the next pass decides with: this pass's symbol counts, plus those
        of the transform trials of key views that JPEG 2000 coded. Without them the intra
        contexts had no counts: the next pass's trial of the intra key, with costs from the
        smoothing alone, could code it at a much lower quality, which JPEG 2000 then matched
        (hci_antinous at step 84.9: the intra key 32.3 dB instead of 37.6, every view 2.2 dB
        lower)."""
        c = self.counts_of(res)
        if res.get("trial_counts") is not None:
            c = c + res["trial_counts"]
        return Model(c + default_counts() * 1e-3)

    def weights_of(self, res: dict) -> np.ndarray:
        """(N0, P, 2) the gains and offsets of a run's weighted predictions, as its file records
        them (the identity, gain 64 and offset 0, for views without one and for intra views)."""
        intra = self.structure_of(res)[4]
        wp = np.zeros((self.n0, self.P, 2), np.int64)
        wp[..., 0] = 64
        for v, c in enumerate(res["codes"]):
            if c is not None and c.wp is not None and not intra[v]:
                wp[v] = c.wp
        return wp

    def pack(self, res: dict) -> tuple[dict, list]:
        """(config, sections) of a run: the tables from every part's counts, then each part's
        streams (a lane's bytes depend on its own symbols and the tables only)."""
        split = self.key_split(res)
        q = quantize_counts(self.counts_of(res, split))
        tables = tables_from_quantized(q)
        streams: list = []
        # parts are coded together until lanes × longest lane reaches PACK_CELLS (a lane's bytes
        # depend on its own symbols only): a key view's few long row streams alone would make
        # thousands of rANS steps of a dozen lanes each
        held: list = []                                  # (lanes, longest lane, part)

        def flush():
            if held:
                off = np.cumsum([0] + [n for n, _, _ in held[:-1]]).tolist()      # (python ints keep the lanes' types)
                cat = [np.concatenate([p[i] + (o if i in (0, 3) else 0) for o, (_, _, p) in zip(off, held)])
                       for i in range(5)]
                streams.extend(pack_streams(sum(n for n, _, _ in held), *cat, tables))
                held.clear()

        for n, part in self.symbol_parts(res, split=split):
            k = int(np.bincount(part[0], minlength=1).max()) if part[0].size else 0
            if held and (sum(h[0] for h in held) + n) * max(k, *(h[1] for h in held)) > PACK_CELLS:
                flush()
            held.append((n, k, part))
        flush()
        coded = self.coded_blocks(res)
        ck = self.coded_keys(res)
        keys, refs, weights, cell, intra = self.structure_of(res)
        nk = len(ck) * self.nby * split
        key_lengths = np.array([len(b) for b in streams[:nk]], np.int64)
        lengths = np.array([len(b) for b in streams[nk:]], np.int64)
        ordered = streams
        intra_keys = [k for k in ck if intra[k]]
        imgs = [res["keyimg"][k] for k in keys if k in res["keyimg"]]
        # one entry per intra key (0 = that view is transform-coded) when any is JPEG 2000
        key_images = tuple(len(res["keyimg"][k]) if k in res["keyimg"] else 0
                           for k in keys if intra[k]) if imgs else ()
        thumbs = np.stack([res["thumbs"][k] for k in intra_keys]) if intra_keys else \
            np.zeros((0, self.nby8, self.nbx8, self.P), np.int64)
        wp = self.weights_of(res)
        weighted = bool(weighted_views(wp).any())
        warped = self.s.warp is not None                # (version 5: version 4's tables, then the warps)
        # version 6: views with alpha, whose JPEG 2000 entries end in their alpha streams
        key_alpha = tuple(len(self.alpha_stream_of(k)) if k in res["keyimg"] else 0
                          for k in keys if intra[k]) if imgs else ()
        alpha = any(key_alpha)
        version = ALPHA_VERSION if alpha else WARP_VERSION if warped else WP_VERSION if weighted else \
            SPLIT_VERSION if split > 1 else VERSION
        warp = self.s.warp if warped or not alpha else np.zeros((self.n0, 4), np.int64)
        lay = TxLayout(self.s.positions, tuple(keys), refs, weights, cell,
                       len(self.s.cell_views), res["steps16"], self.bypass, res["thumb16"],
                       "j2k" if imgs else "tx", key_images, version,
                       split, wp if weighted or warped or alpha else None, warp, key_alpha if alpha else ())
        lay.check("tx encoder")
        # maps no view uses any more (every view of the cell coded alone): the shared map, no modes
        disp, modes = self.disp, self.modes
        unused = np.setdiff1d(np.arange(len(self.s.cell_views)), cell[cell >= 0])
        if unused.size:
            disp, modes = disp.copy(), modes.copy()
            disp[unused], modes[unused] = self.base[None, :], 0
        cfg = {**self.hdr.to_config(), "tx": lay.to_config(),
               "params": {**params_info(self.p), "step": res["step"], "lam_scale": res.get("lam_scale", 1.0)},
               "n_blocks": int(coded.sum()), "n_key_views": len(keys)}
        sections = [("tx.layout", lay.to_bytes()), ("tx.tables", tables_to_bytes(q)),
                    ("tx.maps", pack_maps(self.base, disp, modes, (self.nby8, self.nbx8))),
                    ("tx.thumbs", pack_thumbs(thumbs)), ("tx.keyimg", b"".join(imgs)),
                    ("tx.index", pack_index(key_lengths, coded, lengths)),
                    ("tx.blocks", b"".join(ordered) + bytes(PAD))]
        return cfg, sections
