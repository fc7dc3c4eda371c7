"""Views coded alone as JPEG 2000 by the ``tx`` encoder (:class:`J2kViews`, a part of
:class:`rlfc.txencode.TxEncoder`): a key view, or a view the structure predicts, becomes a
JPEG 2000 image where that is smaller at no more colour error; the gate that decides which views
are worth the search, and the map bytes such a view frees."""
from __future__ import annotations

from typing import TYPE_CHECKING

import math

import numpy as np

from formats.metrics import colour_sq_error
from formats.pixels import to_planes

from .j2ksearch import smallest_j2k
from .txmaps import maps_bytes

if TYPE_CHECKING:
    from .txencode import TxEncoder, ViewCode


class J2kViews:
    """JPEG 2000 views; reads the encoder's views, structure and maps."""

    #: a JPEG 2000 intra key may land this much (dB) below its transform coding's PSNR (the
    #: rate control measures the decoded views, whichever codec made them)
    J2K_KEY_SLACK_DB = 0.05
    #: a view is tried as JPEG 2000 only where its transform coding costs at least this share of
    #: the JPEG 2000 size the run's intra key predicts for it (a gate, so that grids whose views
    #: predict well spend no JPEG 2000 encodes)
    J2K_TRY_SHARE = 0.85

    def _j2k_view(self, v: int, tx_code: ViewCode, extra_bytes: float, slack_db: float,
                  give_up: bool = True, start: dict | None = None,
                  threads: int = 1) -> tuple[bytes | None, ViewCode, float | None]:
        """View v as JPEG 2000 (its padded Hp×Wp image) with colour error at most its transform
        coding's (less ``slack_db``), where that is smaller than the transform path (the model's
        estimate of its streams + ``extra_bytes``); else (None, the transform coding).

        Returns:
            (codestream or None, the view's code, bytes of the smallest JPEG 2000 that met the
            budget where the search found one, else None; with ``give_up=False`` the search
            does not stop at the transform path's size, so the size is there for reference;
            ``start``: where a view not searched before starts, instead of the last view
            searched, which is then left as it is; ``threads``: OpenJPEG's, for a search
            that runs alone).
        """
        orig = self.view_pixels(v)
        budget = tx_code.sse * 10 ** (slack_db / 10)
        target = self._code_psnr(tx_code)
        tx_bytes = tx_code.bits / 8 + extra_bytes

        def err(dec):
            return colour_sq_error(orig, dec[:self.h, :self.w_px])[0]

        # where OpenJPEG lands for this view, kept across the passes of rate control (a view not
        # searched before starts from the last view's)
        hint = self._j2k_hints.setdefault(v, dict(self._j2k_hints.get("last", {}) if start is None else start))
        found = smallest_j2k(self.padded(orig), budget, err, target, tx_bytes if give_up else math.inf, hint,
                             threads=threads, alpha=self.alpha_stream_of(v))
        if start is None:
            self._j2k_hints["last"] = hint
        if found is None or len(found[0]) >= tx_bytes:
            return None, tx_code, (len(found[0]) if found is not None else None)
        data, dec = found
        rec = to_planes(dec)
        crop = self._pixels(rec)                      # the view's own size (the image coded is padded)
        sse, cnt = colour_sq_error(orig, crop)
        return data, self.image_code(crop, rec, sse, cnt), len(data)

    def _code_psnr(self, code: ViewCode) -> float:
        """Colour PSNR (dB) of one coded view."""
        return 10 * math.log10(float(self.peak) ** 2 * code.cnt / max(code.sse, 1e-30))

    def _j2k_worth_trying(self, code: ViewCode, ref: tuple | None, extra_bytes: float = 0.0) -> bool:
        """Whether a view coded as ``code`` (plus ``extra_bytes`` of side information it alone
        needs) might be smaller as JPEG 2000, from ``ref`` = (bytes, PSNR) of the run's intra key
        as JPEG 2000: about twice the bytes per 6 dB."""
        if ref is None or code.sse <= 0:
            return False
        return code.bits / 8 + extra_bytes >= self.J2K_TRY_SHARE * ref[0] * 2.0 ** ((self._code_psnr(code) - ref[1]) / 6.0)

    def _map_bytes(self, k: int) -> float:
        """Bytes of the maps section that predicted key k's own map costs (its cell holds k
        alone: coded alone as JPEG 2000, the key frees it): the section's size with and without
        that map, for every such key at once on the first call (estimated:
        :func:`rlfc.txmaps.maps_bytes`, as the transform path's streams are); 0 where the cell
        has other views."""
        if not self._map_cost:                   # every such key at once
            alone = [(int(v), int(self.s.cell[v])) for v in self.s.keys
                     if self.s.cell[v] >= 0 and list(self.s.cell_views[int(self.s.cell[v])]) == [v]]
            variants = [(self.disp, self.modes)]
            for _, c in alone:
                disp, modes = self.disp.copy(), self.modes.copy()
                disp[c], modes[c] = self.base, 0
                variants.append((disp, modes))
            sizes = maps_bytes(self.base, variants, (self.nby8, self.nbx8))
            self._map_cost = {"all": sizes[0], **{v: float(sizes[0] - n) for (v, _), n in zip(alone, sizes[1:])}}
        return self._map_cost.get(k, 0.0)

    def promote_views(self, res: dict, limits=None) -> list:
        """Code as JPEG 2000 every view that is not a key view whose transform coding is larger
        than JPEG 2000 at no more error (noise-dominated captures at high rates): it becomes an
        intra key view (decoded whole when a request first needs it, no stream, no map), appended to the key
        order; nothing else changes (no view is predicted from it). Keeps the key views within
        the open-time pixel limit. Changes ``res`` in place; returns the views promoted."""
        from formats.limits import DEFAULT

        ref = res.get("j2k_ref")
        if ref is None or self.intra_codec != "j2k":
            return []
        cap = (limits or DEFAULT).max_open_pixels // (self.Hp * self.Wp) - len(self.s.keys)
        done = []
        for v in range(self.n0):
            c = res["codes"][v]
            if len(done) >= cap or self.is_key[v] or c is None or not self._j2k_worth_trying(c, ref):
                continue
            img, code, _ = self._j2k_view(v, c, 1.5 * float(c.coded.sum()), 0.0)
            if img is not None:
                res["codes"][v] = code
                res["keyimg"][v] = img
                done.append(v)
        res["promoted"] = res.get("promoted", []) + done
        return done


def _dct_task(enc: TxEncoder, v: int) -> tuple[tuple[np.ndarray, int], float]:
    """(:func:`rlfc.j2kalloc.dct_samples`, :func:`rlfc.j2kalloc.smooth_psnr`) of view v."""
    from .j2kalloc import dct_samples, smooth_psnr

    px = enc.view_pixels(v)
    return dct_samples(px), smooth_psnr(px)
