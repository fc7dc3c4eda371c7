"""The closed-loop passes of the ``tx`` encoder (:class:`PassCoder`, a part of
:class:`rlfc.txencode.TxEncoder`): every view coded at one quantizer step, key views first
(one after another, or as tasks that wait on their references), then the others on threads or
a runner's workers; a pass of every view as JPEG 2000; the results' decoded pixels and PSNR.
Each pass gives the same integers whatever the threads or workers."""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from formats import parallel as _parallel
from formats.metrics import colour_sq_error, psnr_from_sq_error
from formats.parallel import Runner
from formats.scenes.common import ImageFile

from .txmodel import Model, default_counts
from .txpredict import planar
from .txsample import KeyAtlas
from .txsections import pack_thumbs

if TYPE_CHECKING:
    from .txencode import TxEncoder, ViewCode


class PassCoder:
    """The passes; reads the encoder's structure, maps and codes views with its methods."""

    # -- the closed loop -------------------------------------------------------------------------
    def run(self, step: float, model: Model, progress=None, keep_pixels: bool = False, views=None,
            lam_scale: float = 1.0) -> dict:
        """Code every view at luma step Δ = ``step``: key views in order, then the others (only
        those in ``views`` where given: a sample for rate control; the others' codes are None;
        where every view is an intra key, the keys in ``views`` and the first); ``lam_scale``
        multiplies λ (rate control's trim between two quantizer steps).

        Returns:
            dict with steps16, thumb16, thumbs (per intra key), codes (per view ViewCode), kept
            (``keep_pixels`` was asked: the pass a file may be written from, pixels held or not),
            and with ``keep_pixels`` and :attr:`keep_decoded` pixels: the (N0, H, W, C) decoded
            views, which the codes' ``px`` are views of (one buffer: no per-view copies to gather
            at the end).
        """
        s16 = self.steps16(step)
        keep = bool(keep_pixels) and self.keep_decoded      # (the run is "kept" all the same: res["kept"])
        pix = np.empty((self.n0,) + self.lf.views.shape[2:], self.dtype) if keep else None

        # (every view of a posed capture keeps its decoded pixels in its code, so that any pass
        # can be the file's: the intra keys coded ahead do, and so does the first)
        own_px = self.all_intra and self.keep_decoded

        def px_slot(v):             # where view v's decoded pixels go (in this process)
            return pix[v] if pix is not None else own_px

        hints = {k: dict(h) for k, h in self._j2k_hints.items()}     # (a rerun of this pass starts from them)
        lam_k = self.p.lam * lam_scale * (s16[0, 0] / 16.0) ** 2
        lam_n = self.p.lam * lam_scale * (s16[1, 0] / 16.0) ** 2
        n0 = self.n0
        # the decoded key views, for the views predicted from them (none where every view is
        # intra): sampled from an atlas (filled key by key), else (views OpenCV cannot take) from
        # a planar copy of an int32 stack, rebuilt as keys arrive
        kp = keyplanes = None
        if not self.all_intra:
            kp = self.key_atlas(len(self.s.keys))
            if kp is None:
                keyplanes = np.zeros((len(self.s.keys), self.Hp, self.Wp, self.P), np.int32)
                kp = planar(keyplanes)
        codes: list = [None] * n0
        thumbs = {}
        keyimg = {}
        promoted: list = []           # views coded alone as JPEG 2000 that the structure predicts
        j2k_ref = None                # (bytes, PSNR) of the first intra key as JPEG 2000
        thumb16 = None
        trial_counts = None           # symbols of the transform trials of keys coded as JPEG 2000

        def add_trial(tc):
            nonlocal trial_counts
            trial_counts = tc if trial_counts is None else trial_counts + tc
        pre: dict = {}                # intra keys coded ahead, together (every view intra: posed captures)
        keys = self.s.keys
        if views is not None and self.all_intra:       # (every view an intra key: a sample of them, and the first)
            wanted = set(np.asarray(views).tolist())
            keys = [k for k in keys if k == keys[0] or k in wanted]
        # a grid (one intra key, the first; the others predicted, sampled from the atlas): the
        # keys after the first, and the other views, as tasks that wait on their references
        # (:meth:`_dag_pass`; on a few threads), the same integers as one after another
        dag = (isinstance(kp, KeyAtlas) and len(keys) > 1 and bool(self.intra[keys[0]])
               and not self.intra[list(keys[1:])].any())
        for i, k in enumerate(keys):
            if dag and i >= 1:
                break
            if i == 1 and self.all_intra and len(keys) > 2 and (self.intra_codec != "j2k" or j2k_ref):
                pre = self._code_intra_keys(keys[1:], thumb16, s16[0], lam_k, model,
                                             pix if pix is not None else own_px)
            ahead = k in pre
            if ahead:                           # (JPEG 2000 tried there too)
                thumbs[k], codes[k], img, tc = pre.pop(k)
                if img is not None:
                    keyimg[k] = img
                    add_trial(tc)
            elif self.intra[k]:
                # the thumbnail's step (one per file): exact block means (flat regions need no
                # residual at all) or the key step (textured views), whichever costs less (colour
                # squared error + λ·bits) for the first intra view; the others use the same. (By
                # bits alone, a model measured at another step could pick the key step's coarse
                # thumbnail at 6 dB less: hci_antinous at step 120.5, 46 738 bits at 30.4 dB
                # against 50 900 at 36.1.) A pass at a key step an earlier pass chose at takes
                # that choice (rate control runs a step again with another model or other maps; the
                # files of six grids at 40 and 45 dB were the same on 10 of 12, within ±0.03% on the
                # other two, with 25% fewer trials of ~60 ms of CPU each: BENCHMARKS.md).
                lam_rgb = lam_k * (3.0 if self.P >= 3 else 1.0)   # a luma error e is e in each of R, G, B
                best = None
                key16 = int(s16[0, 0])
                if thumb16 is not None:
                    cands = [thumb16]
                elif key16 in self._thumb_at:
                    cands = [self._thumb_at[key16]]
                else:
                    cands = sorted({16, key16})
                # (several candidates: each keeps its own pixels, gathered at the end; coded side
                # by side on threads, the same integers, from the view read once here)
                opx = self.view_pixels(k) if len(cands) > 1 else None
                got = Runner().map_threaded(self.code_intra, [(k, t16, s16[0], lam_k, model,
                                                               px_slot(k) if len(cands) == 1 else keep or own_px,
                                                               opx) for t16 in cands])
                for t16, (lv, c) in zip(cands, got):
                    cost = c.sse + lam_rgb * (c.bits + 8 * len(pack_thumbs(lv[None])))
                    if best is None or cost < best[0]:
                        best = (cost, t16, lv, c)
                _, thumb16, thumbs[k], codes[k] = best
                self._thumb_at.setdefault(key16, thumb16)
            else:                               # (as :meth:`_dag_pass` codes them, one after another)
                codes[k], img, tc, _ = _pass_task(self, "key", k, kp, model, s16[0], lam_k, lam_k / lam_scale,
                                                  px_slot(k), j2k_ref, None)
                if img is not None:
                    keyimg[k] = img
                    promoted.append(k)
                    add_trial(tc)
            if not ahead and self.intra[k] and self.intra_codec == "j2k":
                trial = codes[k]
                # (the pass's first key: every other view waits on it, so OpenJPEG gets the threads)
                img, codes[k], size = self._j2k_view(k, codes[k], len(pack_thumbs(thumbs[k][None])),
                                                     self.J2K_KEY_SLACK_DB, give_up=j2k_ref is not None,
                                                     threads=_parallel.LOCAL_THREADS if i == 0 else 1)
                if img is not None:
                    keyimg[k] = img
                    add_trial(self._key_symbols(k, trial, True))
                if j2k_ref is None and size is not None:
                    j2k_ref = (size, self._code_psnr(codes[k]))
            if isinstance(kp, KeyAtlas):
                kp.set(i, codes[k].planes)
            elif keyplanes is not None:
                keyplanes[i] = codes[k].planes
                kp = planar(keyplanes)
            codes[k].planes = None              # (kept once, in the atlas or keyplanes, for this pass only)
            if progress:
                progress("code views", i + 1, n0)
        others = all_others = [v for v in range(n0) if not self.is_key[v]]
        if views is not None:            # a sample of the other views (rate control's search)
            keep = set(int(v) for v in views)
            others = [v for v in others if v in keep]
        runner = self.runner or Runner()
        here = runner.kind == "serial" or runner.workers == 1 or len(others) < 2
        if dag:
            got = self._dag_pass(keys, others if here else [], kp, model, s16, lam_k, lam_n, lam_scale, j2k_ref,
                                 px_slot, progress)
            for k, (code, img, tc) in zip(keys[1:], got):
                codes[k] = code
                if img is not None:
                    keyimg[k] = img
                    promoted.append(k)
                    add_trial(tc)
            for v, c in zip(others if here else [], got[len(keys) - 1:]):
                codes[v] = c
            if here:
                others = []
        done = [len(self.s.keys)]

        def tick(n):
            done[0] += n
            if progress:
                progress("code views", done[0], n0)

        # the other views are independent given the decoded key views: in this process on a few
        # threads (the same integers), else on the runner's workers
        if not others:
            out = []
        elif here:
            out = Runner().map_threaded(_code_task, [(self, kp, model, v, None, s16[1], lam_n, px_slot(v),
                                                    lam_n / lam_scale) for v in others], tick)
        else:
            if self._shared is None:
                self._shared = runner.share(self)
                self._view_handles = self._worker_views(runner, all_others)
            keys_h, model_h = runner.share(kp), runner.share(model)

            def take(i, c):             # a worker's decoded pixels go into the pass's buffer as they arrive
                if pix is not None and c.px is not None:
                    pix[others[i]] = c.px
                    c.px = pix[others[i]]
                return c

            out = runner.map(_code_task, [(self._shared, keys_h, model_h, v, self._view_handles[v], s16[1], lam_n,
                                           keep, lam_n / lam_scale) for v in others], tick, take)
        for v, c in zip(others, out):
            codes[v] = c
        res = {"steps16": s16, "thumb16": thumb16 or 16, "thumbs": thumbs, "codes": codes, "step": step,
               "keyimg": keyimg, "model": model, "promoted": promoted, "j2k_ref": j2k_ref,
               "lam_scale": lam_scale, "j2k_hints": hints, "trial_counts": trial_counts, "kept": bool(keep_pixels)}
        if pix is not None:
            res["pixels"] = pix
            self._gather_pixels(res)
        return res

    def _dag_pass(self, keys: list, others: list, kp: KeyAtlas, model: Model, s16: np.ndarray, lam_k: float,
                  lam_n: float, lam_scale: float, j2k_ref, px_slot, progress) -> list:
        """The predicted keys ``keys[1:]`` (the first, the intra key, is in the atlas) and the views
        ``others``, each a task that starts once the key views it predicts from are decoded
        (:meth:`formats.parallel.Runner.map_dag`: keys first, a few threads; a key's decoded planes
        go into ``kp`` before any view that reads them starts). A key that has never been tried
        as JPEG 2000 starts its search where the intra key's ended (one after another, from the
        previous key's: the order threads finish in must not matter).

        Returns:
            [(code, JPEG 2000 codestream or None, its trial's symbol counts or None) per key after
            the first] + [code per view of ``others``].
        """
        rest = list(keys[1:])
        at = {int(k): i for i, k in enumerate(rest)}
        start = dict(self._j2k_hints.get("last", {}))
        if self.intra_codec == "j2k":
            self._map_bytes(int(rest[0]))          # (made once here, not by two threads at once)
        lam_fit_k, lam_fit_n = lam_k / lam_scale, lam_n / lam_scale
        args, deps = [], []
        for k in rest:
            args.append((self, "key", int(k), kp, model, s16[0], lam_k, lam_fit_k, px_slot(k), j2k_ref, start))
            deps.append([at[int(r)] for r in self.s.refs[k] if r >= 0 and int(r) in at])
        for v in others:
            args.append((self, "view", int(v), kp, model, s16[1], lam_n, lam_fit_n, px_slot(v), None, None))
            deps.append([at[int(r)] for r in self.s.refs[v] if r >= 0 and int(r) in at])
        count = [len(keys) - len(rest)]

        def finish(i, r):
            if i < len(rest):
                k = rest[i]
                kp.set(int(self.key_slot[k]), r[0].planes)
                r[0].planes = None                # (kept once, in the atlas, for this pass only)
            count[0] += 1
            if progress:
                progress("code views", count[0], self.n0)
            return r

        out = Runner().map_dag(_pass_task, args, deps, finish)
        searched = [k for k, r in zip(rest, out) if r[3]]
        if searched:
            self._j2k_hints["last"] = self._j2k_hints[searched[-1]]
        return [r[:3] for r in out[:len(rest)]] + out[len(rest):]

    def run_j2k(self, levels: np.ndarray, step: float, progress=None) -> dict:
        """Every view (a posed capture's: each an intra key) as JPEG 2000 at its own OpenJPEG
        quality ``levels`` (n0,) (dB): a run as :meth:`run` returns it, with no transform-coded
        view (``step`` is only recorded; a grid's views that the plan predicts are "promoted":
        intra keys of the file). The views are coded on a few threads (OpenJPEG releases the
        GIL); their decoded pixels are kept where :attr:`keep_decoded` says."""
        keep = self.keep_decoded
        done = [0]

        def tick(n):
            done[0] += n
            if progress:
                progress("code views", done[0], self.n0)

        out = Runner().map_threaded(_j2k_task, [(self, v, float(levels[v]), keep) for v in range(self.n0)], tick)
        res = {"steps16": self.steps16(step), "thumb16": 16, "thumbs": {}, "codes": [c for _, c in out], "step": step,
               "keyimg": {v: data for v, (data, _) in enumerate(out)}, "model": Model(default_counts()),
               "promoted": np.flatnonzero(~self.intra).tolist(), "j2k_ref": None, "lam_scale": 1.0,
               "j2k_hints": {}, "trial_counts": None, "kept": True}
        if keep:
            res["pixels"] = np.empty((self.n0,) + self.lf.views.shape[2:], self.dtype)
            self._gather_pixels(res)
        return res

    @staticmethod
    def _gather_pixels(res: dict) -> None:
        """Copy into ``res["pixels"]`` the decoded views that live elsewhere (JPEG 2000 views,
        workers' results) and make their codes' ``px`` views of it."""
        pix = res["pixels"]
        for v, c in enumerate(res["codes"]):
            if c is not None and c.px is not None and not np.may_share_memory(c.px, pix):
                pix[v] = c.px
                c.px = pix[v]

    def _code_intra_keys(self, ks: list, thumb16: int, s16k: np.ndarray, lam_k: float, model: Model,
                         keep_pixels: np.ndarray | bool | None) -> dict:
        """Intra key views ``ks`` after the first (which chose the thumbnail step and the JPEG 2000
        reference), coded as the pass would code them one by one, on a few threads (``keep_pixels``:
        the pass's buffer of decoded views, or None to keep none): view →
        (thumbnail levels, code, JPEG 2000 codestream or None, symbol counts of the transform
        trial where JPEG 2000 won, else None). A view's JPEG 2000 search with no
        hint of its own starts from the first view's (one after another, from the previous
        view's: the order threads finish in must not matter)."""
        first = dict(self._j2k_hints.get("last", {}))
        for k in ks:
            self._j2k_hints.setdefault(k, dict(first))
        out = Runner().map_threaded(_intra_key_task, [(self, k, thumb16, s16k, lam_k, model,
                                                       keep_pixels[k] if isinstance(keep_pixels, np.ndarray) else
                                                       keep_pixels) for k in ks])
        if ks:
            self._j2k_hints["last"] = self._j2k_hints[ks[-1]]
        return dict(zip(ks, out))

    def decoded(self, res: dict) -> np.ndarray | None:
        """(R, C, H, W, Ch) pixels of a run (the run again, keeping pixels, where it kept none:
        the same integers): the run's buffer, with the views coded after it (promoted views);
        None where the encoder keeps no decoded views (``keep_decoded``)."""
        if not self.keep_decoded:
            return None
        res = self.with_pixels(res)
        self._gather_pixels(res)
        return res["pixels"].reshape(self.lf.views.shape)

    def with_pixels(self, res: dict) -> dict:
        """``res``, or the same run again keeping the decoded pixels where it kept none (the
        same integers); without ``keep_decoded``, the same run over every view where it covered
        a sample only."""
        if any(c is None for c in res["codes"]) or self.keep_decoded and any(c.px is None for c in res["codes"]):
            # the JPEG 2000 searches start where they started in that pass: the same codestreams
            self._j2k_hints = {k: dict(h) for k, h in res.get("j2k_hints", {}).items()}
            return self.run(res["step"], res["model"], keep_pixels=True, lam_scale=res.get("lam_scale", 1.0))
        if self.keep_decoded and "pixels" not in res:      # every view's pixels kept in its code (key views: a posed capture)
            res = dict(res, pixels=np.empty((self.n0,) + self.lf.views.shape[2:], self.dtype))
            self._gather_pixels(res)
        return res

    def psnr(self, res: dict) -> float:
        """Colour PSNR of a run over all views (exactly :func:`formats.metrics.psnr_rgb`); of a
        run over a sample of the other views (``run(views=...)``), the estimate that counts each
        sampled view for the other views it stands for (key views exactly)."""
        c = res["codes"]
        done = [v for v, x in enumerate(c) if x is not None]
        w = np.ones(len(done))
        sampled = [i for i, v in enumerate(done) if not self.is_key[v]]
        n_other = int((~self.is_key).sum())
        if len(done) < len(c) and sampled:
            w[sampled] = n_other / len(sampled)
        return psnr_from_sq_error(w * np.array([c[v].sse for v in done]), w * np.array([c[v].cnt for v in done]),
                                  float(self.peak))

    def view_psnrs(self, res: dict) -> np.ndarray:
        """(views,) colour PSNR of each view of a run over every view (inf where exact; exactly
        :func:`formats.metrics.psnr_views` of its decoded views)."""
        return np.array([psnr_from_sq_error(c.sse, c.cnt, float(self.peak)) for c in res["codes"]])


def _j2k_task(enc: TxEncoder, v: int, level: float, keep: bool) -> tuple[bytes, ViewCode]:
    """View v's padded image as JPEG 2000 at OpenJPEG's quality ``level`` (dB): (codestream,
    its code: no tbs, the colour error over the view's own pixels, the pixels where ``keep``)."""
    from .topcodec import j2k_round_trip

    orig = enc.view_pixels(v)
    data, dec = j2k_round_trip(enc.padded(orig), level, 1, enc.alpha_stream_of(v))
    crop = dec[:enc.h, :enc.w_px]
    sse, cnt = colour_sq_error(orig, crop)
    return data, enc.image_code(np.ascontiguousarray(crop) if keep else None, None, sse, cnt)


def _code_task(enc: TxEncoder, kp: np.ndarray, model: Model, v: int, pixels: np.ndarray,
               step16: np.ndarray, lam: float, keep_pixels, lam_fit: float | None = None) -> ViewCode:
    """One view that is not a key view, coded on a worker (the same integers as in the parent);
    ``kp`` the pass's decoded key views (:meth:`TxEncoder.key_atlas`, or planar planes);
    ``keep_pixels``, ``lam_fit`` as :meth:`TxEncoder.code_view`; ``pixels`` the view's (H, W, C)
    pixels or its image file (read here)."""
    if isinstance(pixels, ImageFile):
        pixels = pixels.read()
    return enc.code_view(v, enc.predict_view(v, kp), step16, lam, model, pixels, keep_pixels, lam_fit)


def _pass_task(enc: TxEncoder, what: str, v: int, kp: KeyAtlas, model: Model, step16: np.ndarray, lam: float,
               lam_fit: float, keep_pixels, j2k_ref, start) -> tuple | ViewCode:
    """One task of :meth:`TxEncoder._dag_pass`: a view that is not a key view (its code), or a
    predicted key view: (its code, kept with its decoded planes; the JPEG 2000 codestream where
    coding it alone as JPEG 2000 is smaller (``j2k_ref``: the pass's intra key as JPEG 2000),
    else None; that case's transform trial's symbol counts; whether JPEG 2000 was tried;
    ``start``: where a first JPEG 2000 search starts, None: where the last one ended)."""
    code = _code_task(enc, kp, model, v, None, step16, lam, keep_pixels, lam_fit)
    if what == "view":
        return code
    img = tc = None
    tried = enc.intra_codec == "j2k" and enc._j2k_worth_trying(code, j2k_ref, enc._map_bytes(v))
    if tried:
        # a predicted key that costs more than coding it alone (its streams and the map that
        # only it uses) becomes an intra key
        trial = code
        img, code, _ = enc._j2k_view(v, code, enc._map_bytes(v), enc.J2K_KEY_SLACK_DB, start=start)
        if img is not None:
            tc = enc._key_symbols(v, trial, True)
    return code, img, tc, tried


def _intra_key_task(enc: TxEncoder, k: int, thumb16: int, s16k: np.ndarray, lam_k: float, model: Model,
                    keep_pixels) -> tuple:
    """One intra key view that is not the first of its pass (:meth:`TxEncoder._code_intra_keys`)."""
    lv, code = enc.code_intra(k, thumb16, s16k, lam_k, model, keep_pixels)
    img = tc = None
    if enc.intra_codec == "j2k":
        trial = code
        img, code, _ = enc._j2k_view(k, code, len(pack_thumbs(lv[None])), enc.J2K_KEY_SLACK_DB, give_up=True)
        if img is not None:             # (the next pass's model counts the transform trial)
            tc = enc._key_symbols(k, trial, True)
    code.planes = None                  # (no view is predicted from it)
    return lv, code, img, tc
