"""Rate control of the ``tx`` profile, and its encode: the search for the quantizer step (and
λ, the key views' share, JPEG 2000 levels of intra views) that meets a PSNR or size target
with the fewest bytes, each evaluation a closed-loop pass of :class:`rlfc.txencode.TxEncoder`;
the probe pass, the maps' repricing at the coding λ, the λ trim, and the file's summary.
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from formats.codec_api import EncodeOptions, Encoded, is_real
from formats.errors import ParameterError
from formats.metrics import finite
from formats.parallel import Runner, make_runner

from .params import flags
from .txlayout import weighted_views
from .ratesearch import secant_search
from .txmaps import maps_bytes
from .txencode import TxEncoder
from .txj2kview import _dct_task
from .txmodel import Model, default_counts
from .txparams import TxParams, params_info


def _params_from(options: EncodeOptions) -> TxParams:
    p = dict(options.params)
    known = {f for f in TxParams.__dataclass_fields__} | {"quant"}
    bad = sorted(set(p) - known)
    if bad:
        raise ParameterError(f"option(s) {flags(bad)} not used by profile "
                             "'tx'")
    q = p.pop("quant", None)
    if q is not None:
        if options.target_psnr is not None or options.target_bpp is not None or options.lossless:
            raise ParameterError("--quant cannot be combined with a target or --lossless")
        if not is_real(q) or not q >= 1:
            raise ParameterError(f"--quant must be a number >= 1 (1 = lossless), got {q!r}")
        if q == 1:
            p["lossless"] = True
        else:
            p["step"] = float(q)
    if options.lossless:
        if options.target_psnr is not None or options.target_bpp is not None:
            raise ParameterError("--lossless cannot be combined with a target")
        p["lossless"] = True
    return TxParams(**p)


FINEST_NOTE = "even the finest quantizer misses the target; the closest setting is written"
COARSEST_NOTE = ("even the coarsest quantizer (and the smallest key views) cannot reach this bpp; the closest "
                 "setting is written")
SEARCH_STRIDE = 4      # the search's sample: every 4th view that is not a key view …
SEARCH_MIN_VIEWS = 16  # … where there are at least this many
MODEL_REACH = 0.25    # octaves of the step: a search evaluation codes with the entropy model measured
                      # nearest to its step where one is this near (else it measures one first)
MAPS_REPRICE_RATIO = 1.25  # a PSNR or size target's maps are repriced where the probe puts the coding λ at least
                           # this many times the λ they were estimated for, and kept where the coded check
                           # says so (4 until stop 65: BENCHMARKS.md)
MODEL_SPAN = 1.5      # octaves: a search evaluation between two measured models at most this far apart
                      # codes with their counts interpolated (no pass of its own to measure one)
SEARCH_MIN_WIDTH = 1 / 32   # octaves: a PSNR search ends when a step that met the target and one that
                            # missed are this close (the staircase below it is noise: BENCHMARKS.md)
PSNR_SLOPE = -2.5    # dB per octave of the step around 40 dB (dense grids: 2.2-2.8), the search's prior
#: dB per octave of the step from the probe pass to the step a PSNR target settles at, where the
#: probe lands above the target (the step goes coarser) and below it (finer). Measured on the six
#: dense grids at 36 / 40 / 45 dB: 1.2–2.9 (median 2.0) and 2.1–5.2 (median 3.5). The coarse side
#: stays at PSNR_SLOPE: -2.0 there grew files 0.9–1.8% (the maps repriced further from the
#: target); -3.5 on the fine side saves a pass on most searches, files within ±0.4%
#: (BENCHMARKS.md, "The probe's slope, by direction")
PROBE_SLOPES = (PSNR_SLOPE, -3.5)
BPP_SLOPE = -1.0     # log2 bpp per octave of the step, the same for a bpp target

#: posed captures coded as JPEG 2000 (a PSNR target): the first shift of the views' levels
#: above their shares of the error (OpenJPEG lands 0.3–0.7 dB under the level asked on the LLFF
#: captures), and how far above the target a pass may land and end the search (dB)
J2K_FIRST_DB = 0.45
J2K_TOL_DB = 0.03
#: every view's thumbnail alone (:func:`rlfc.j2kalloc.smooth_psnr`) must stay this far below the
#: target for JPEG 2000 to be taken without trying the transform path (dB; the LLFF captures are
#: 2.3 dB and more below at 36 dB, where the full search coded every view as JPEG 2000)
J2K_SMOOTH_MARGIN_DB = 2.0
#: a size target's first pass takes the views' shares at this PSNR (dB), then at the PSNR that
#: pass says the size reaches, at this many dB per doubling of the size (JPEG 2000 on the LLFF
#: captures between 36 and 40 dB: 3.2–4.6)
J2K_BPP_FIRST_DB = 40.0
J2K_DB_PER_OCTAVE = 4.0
#: a per-view floor lifts the views' shares to this much above it (dB)
J2K_FLOOR_MARGIN_DB = 0.1
#: the transform path's step at a PSNR over the open-loop step that rounds the views' 8×8 DCT to
#: that PSNR (:func:`rlfc.j2kalloc.step_prior`; its rate-distortion decisions zero more): 1.21–1.65
#: on six posed encodes (the LLFF captures at 36 and 40 dB, mitsuba_objects_360 at 40 dB)
PROXY_STEP_RATIO = 1.4


def _search_j2k_levels(enc: TxEncoder, target_psnr: float | None, target_bpp: float | None, step: float,
                       samples: list, trace: list, progress, floor: float | None = None) -> tuple[dict, bool]:
    """A posed capture's views as JPEG 2000 meeting a pooled colour PSNR ``target_psnr`` (at
    least) or a file size ``target_bpp`` (at most: the best quality within it), searched on
    OpenJPEG's own quality levels instead of through the transform path (which coded every view
    both ways in every pass): each view's share of the error from one uniform quantizer step
    (:func:`rlfc.j2kalloc.share_psnrs` of the views' ``samples``, open loop), then a secant on
    one shift of every view's level. For a size, the shares are taken at the PSNR a first pass
    (shares at J2K_BPP_FIRST_DB) says the size reaches. A per-view ``floor`` (dB, with a PSNR
    target) lifts the shares below it to it and is searched with the pooled target: the shift
    stops where either would be missed. Returns (the run the search prefers among those that
    met the target, else the closest; whether one met it)."""
    from .j2kalloc import MAX_LEVEL, MIN_LEVEL, share_psnrs

    peak, ones = float(enc.peak), np.ones(enc.n0)

    def code(share, q):
        res = enc.run_j2k(np.clip(share - q, MIN_LEVEL, MAX_LEVEL), step, progress)
        ps = enc.psnr(res)
        b = file_bpp(enc.lf, *enc.pack(res))
        trace.append({"j2k_shift": -q, "psnr_rgb": ps, "bpp": b})
        return res, ps, b

    if target_bpp is None:
        share = share_psnrs(samples, ones, peak, target_psnr)
        target, slope0, tol = target_psnr, -1.0, J2K_TOL_DB
        if floor is not None:                  # (the views' landing spreads ~0.1 dB about their levels)
            share = np.maximum(share, floor + J2K_FLOOR_MARGIN_DB)

        def value(q):                          # q = −shift: the PSNR falls as q grows
            res, ps, _ = code(share, q)
            if floor is not None:              # the margin the nearer of the two targets leaves
                ps = target + min(ps - target, float(enc.view_psnrs(res).min()) - floor)
            return ps, res
    else:
        _, p0, b0 = code(share_psnrs(samples, ones, peak, J2K_BPP_FIRST_DB), -J2K_FIRST_DB)
        at = p0 + J2K_DB_PER_OCTAVE * (math.log2(target_bpp) - math.log2(b0))
        share = share_psnrs(samples, ones, peak, min(max(at, 10.0), 120.0))
        target, slope0, tol = math.log2(target_bpp), -1.0 / J2K_DB_PER_OCTAVE, 0.01

        def value(q):                          # log2 bpp falls as q grows
            res, _, b = code(share, q)
            return math.log2(max(b, 1e-12)), res

    sr = secant_search(value, -J2K_FIRST_DB, target, feasible_above=target_bpp is None, slope0=slope0,
                       lo=float(share.min() - MAX_LEVEL), hi=float(share.max() - MIN_LEVEL), tol=tol,
                       snap=lambda q: round(q * 256) / 256)
    return sr.result, sr.found


SIDE_SCALE = 6.0   # side information is judged open loop on the original key views, which flatters it:
                   # measured best at 6..10 × the coding λ on the dense grids (BENCHMARKS.md)
#: views with alpha: side information judged at this share of the colour's λ. Their alpha plane is
#: coded exactly whatever the target, so each alpha sample a map or mode predicts wrong costs bits
#: the luma cost does not see, as much at 36 dB as at 45; on an RGBA grid (tools.unseen
#: layers_rgba_9x9) the file at 36 / 40 / 45 dB was 0.79 / 0.87 / 0.94× at 0.03 of the λ,
#: 0.78 / 0.88 / 0.94× at 0.01 (BENCHMARKS.md)
ALPHA_SIDE_SCALE = 1 / 32


def side_lambda(lf, options: EncodeOptions, params: TxParams) -> float:
    """λ for side-information decisions (luma squared error per bit) at the expected quality:
    SIDE_SCALE·lam·Δ² with Δ² ≈ 12·D, D the mean squared error the target allows (or the
    default step's); × ALPHA_SIDE_SCALE for views with alpha."""
    from .ratecontrol import depth_scale

    peak = float(np.iinfo(lf.views.dtype).max)
    if params.lossless:
        d = 1 / 12
    elif options.target_psnr is not None:
        d = peak ** 2 * 10 ** (-options.target_psnr / 10)
    elif params.step is not None:
        d = params.step ** 2 / 12
    else:
        d = (8.0 * depth_scale(lf.views.dtype)) ** 2 / 12
    alpha = ALPHA_SIDE_SCALE if lf.has_alpha else 1.0
    return SIDE_SCALE * params.lam * 12 * d * alpha


def file_bytes(lf, cfg: dict, sections: list) -> int:
    """Size of the .lfc file these sections make (container, metadata with the scene and a
    provenance allowance of 1 KiB, as the CLI writes it)."""
    from formats.container import DEFAULT_CHUNK, ENTRY_SIZE, HEADER_SIZE
    from formats.lfcfile import encode_meta

    meta = len(encode_meta("rlfc", 1, cfg, lf.geometry())) + 1024
    data = [meta] + [len(x) for _, x in sections]
    return HEADER_SIZE + ENTRY_SIZE * len(data) + 4 * sum(-(-n // DEFAULT_CHUNK) for n in data) + sum(data)


def file_bpp(lf, cfg: dict, sections: list) -> float:
    """bpp of the .lfc file these sections make (:func:`file_bytes`, per view pixel)."""
    from formats.metrics import bpp

    return bpp(file_bytes(lf, cfg, sections), lf.rows * lf.cols, lf.height, lf.width)


TRIM_DB = 0.08         # a file this far above its PSNR target has λ trimmed at the chosen step
TRIM_SLOPE = -1.25     # dB per octave of λ at a fixed step, the trim's prior (six grids at 36-45 dB:
                       # -0.6 … -1.6, median -1.3; dino at 48 dB: -1.0)
TRIM_TRIES = 3
TRIM_GIVE_UP = 1 / 16  # octaves of λ: a miss this close to a multiplier that met the target ends the
                       # trim (a staircase there: hci_antinous at 36 dB missed at ×1.02-1.07 from 0.084 dB above)


def _trim_lambda(enc: TxEncoder, res: dict, target: float, progress, trace: list) -> dict:
    """The quantizer steps are integers in 1/16 units: at high rates one unit moves the PSNR by
    0.2–0.5 dB, so the search may end well above its target. Between two steps, a larger λ
    (more skipped blocks, fewer coefficients) spends the margin: a secant search over log2 of
    λ's multiplier on full passes, keeping the largest multiplier that still meets the target."""
    ps = enc.psnr(res)
    if ps - target <= TRIM_DB or not res["kept"] or any(c is None for c in res["codes"]):
        return res
    best, lo = res, (0.0, ps)
    miss = None                        # the smallest log2 multiplier that missed the target
    q = min((target + 0.03 - ps) / TRIM_SLOPE, 4.0)
    for _ in range(TRIM_TRIES):
        if miss is not None and miss - lo[0] < TRIM_GIVE_UP:
            break
        if miss is not None and not lo[0] < q < miss:        # the secant left the bracket: bisect it
            q = (lo[0] + miss) / 2
        if q - lo[0] < 1 / 64:
            break
        r = enc.run(res["step"], res["model"], progress, keep_pixels=True, lam_scale=2.0 ** q)
        p = enc.psnr(r)
        trace.append({"step": res["step"], "lam_scale": 2.0 ** q, "psnr_rgb": p, "bpp": None, "refined": True})
        slope = min((p - lo[1]) / (q - lo[0]), -0.05)
        if p >= target:
            if q > math.log2(best.get("lam_scale", 1.0)):
                best = r
            if p - target <= TRIM_DB:
                break
            lo = (q, p)
        else:
            miss = q if miss is None else min(miss, q)
        q = min(lo[0] + (target + 0.03 - lo[1]) / slope, 4.0)
    return best


def _between_models(models: dict, logq: float) -> "Model | None":
    """The entropy model of a search evaluation at log2 step ``logq`` that lies between two
    measured models (``models``: step → Model) at most MODEL_SPAN octaves apart: their counts
    interpolated geometrically in log2 of the step (symbol counts move smoothly with the step;
    on six grids at 36/40/45 dB the files stayed within ±0.01% where the search took the same
    path). None where no measured step lies on each side within that span."""
    lo = max(((math.log2(k), k) for k in models if math.log2(k) < logq), default=None)
    hi = min(((math.log2(k), k) for k in models if math.log2(k) > logq), default=None)
    if lo is None or hi is None or hi[0] - lo[0] > MODEL_SPAN:
        return None
    t = (logq - lo[0]) / (hi[0] - lo[0])
    ca, cb = (np.maximum(models[k].counts, 1e-12) for _, k in (lo, hi))
    return Model(np.exp((1 - t) * np.log(ca) + t * np.log(cb)))


#: log2 bytes that one dB of PSNR costs near a target (BPP_SLOPE / PSNR_SLOPE): how two runs at one
#: step compare (:func:`_maps_pay_repriced`)
LOG2_BYTES_PER_DB = BPP_SLOPE / PSNR_SLOPE


def _run_cost(enc: "TxEncoder", res: dict, share: float) -> float:
    """log2 of a (sampled) run's estimated file bytes less LOG2_BYTES_PER_DB per dB of its PSNR:
    the smaller, the better at equal quality. The sampled views' stream bits stand for the
    share of the others they are; key streams, JPEG 2000 codestreams and the maps count once."""
    key = oth = 0.0
    for v, c in enumerate(res["codes"]):
        if c is not None:
            if enc.is_key[v]:
                key += c.bits
            else:
                oth += c.bits
    images = sum(len(x) for x in res["keyimg"].values())
    maps = maps_bytes(enc.base, [(enc.disp, enc.modes)], (enc.nby8, enc.nbx8))[0] if enc.has_maps else 0
    return math.log2(max(key / 8 + oth / 8 / share + images + maps, 1.0)) - LOG2_BYTES_PER_DB * enc.psnr(res)


def _maps_pay_repriced(enc: "TxEncoder", step: float, model, ratio: float, sample, n_others: int, models: dict,
                       progress) -> str | None:
    """Code the search's first step with the maps as estimated, with their corrections repriced
    at λ × ``ratio`` and with their modes repriced too (:meth:`TxEncoder.reprice_maps`), the same
    entropy model; keep the maps whose run costs least at equal quality (:func:`_run_cost`; a
    tie keeps the simpler). Corrections that are noise at a coarse step go; those that follow
    an occluder's edge stay (hci_buddha with an occluder at 32 dB: +24% bytes had they gone).
    Modes priced at the coding λ pay on some grids (hci_antinous at 32 dB −16%) and cost on
    others (stanford_chess at 32 dB +2.6%): the three runs decide. The kept run's model is the
    search's at that step.

    Returns:
        None (the maps as estimated), "corrections" or "modes" (which were repriced).
    """
    share = (len(sample) / n_others) if sample is not None and n_others else 1.0
    lam = enc.estimated_lambda
    enc.price_maps_at(lam * ratio)                # both variants at once, from the kept luma, which
    enc.drop_luma(repriced_too=False)             # then goes before any run (a third of an RGB light field)
    best = None                                   # (cost, what, maps, the run's model): only the
    for what in (None, "corrections", "modes"):   # cheapest run so far is held (each holds its views' codes)
        if what is not None:
            enc.reprice_maps(lam * ratio, modes_too=what == "modes")
        run = enc.run(step, model, progress, views=sample)
        cost = _run_cost(enc, run, share)                         # (the maps' bytes: those coded now)
        if best is None or cost < best[0]:
            best = (cost, what, enc.maps(), enc.model_of(run))
        del run
    _, what, maps, best_model = best
    if what is None:
        enc.restore_maps()
    else:
        enc.use_maps(maps)
    models[step] = best_model
    return what


#: a grid whose file codes at least this share of its views alone as JPEG 2000 (high rates on
#: views that predict each other badly: stanford_chess at 45 dB, 47 of 49) also tries every view
#: as JPEG 2000, on OpenJPEG's own levels as a posed capture's views are searched
J2K_ALL_SHARE = 0.5


def _every_view_j2k(enc: TxEncoder, res: dict, options: EncodeOptions, step: float, found: bool, trace: list,
                    progress) -> dict | None:
    """Every view of a grid coded alone as JPEG 2000 (:func:`_search_j2k_levels`), where that
    meets the target and its file is smaller than ``res``'s (a PSNR target; a size target: a
    better PSNR within the size); else None. Where most views are coded alone already, the
    per-view levels this search shares out (one shift of every view's level) reach the target
    with fewer bytes than JPEG 2000 views each matched to its transform coding's error, beside
    a few predicted views and their streams (stanford_chess at 45 dB, BENCHMARKS.md)."""
    nv = enc.n0
    got = Runner().map_threaded(_dct_task, [(enc, v) for v in range(nv)])
    alone, met = _search_j2k_levels(enc, options.target_psnr, options.target_bpp, step, [s for s, _ in got], trace,
                                    progress, options.min_view_psnr if options.target_bpp is None else None)
    if not met:
        return None
    size, size_alone = file_bytes(enc.lf, *enc.pack(res)), file_bytes(enc.lf, *enc.pack(alone))
    if options.target_psnr is not None:
        better = size_alone < size or not found
    else:
        better = not found or enc.psnr(alone) > enc.psnr(res)
    return alone if better else None


CLOSE_TRIES = 2         # full passes that close in on the target after a corrected miss
FALLBACK_OCTAVES = 0.25  # where the finer steps by the prior slope all missed: one pass this much finer


def _close_in(enc: TxEncoder, res: dict, miss: tuple, target: float, progress, trace: list) -> dict:
    """After the sampled search's step missed on every view and the prior slope's finer step
    overshot (PSNR against the step is steep at low rates: hci_antinous at 36 dB missed with
    34.6 dB at step 90.6 and the prior slope's step 61.7 gave 38.5 dB), the secant between the two
    full passes, in log2 of the step on the coder's grid, keeping the largest step that meets the
    target. ``miss``: (log2 step, PSNR) of the pass below the target."""
    ps = enc.psnr(res)
    for _ in range(CLOSE_TRIES):
        if ps - target <= TRIM_DB:
            break
        q_ok = math.log2(res["step"])
        q = q_ok + (target + 0.03 - ps) * (miss[0] - q_ok) / (miss[1] - ps)
        step = enc.grid_step(2.0 ** q)
        if not q_ok < math.log2(step) < miss[0]:       # no grid point strictly inside the bracket
            break
        r = enc.run(step, enc.model_of(res), progress, keep_pixels=True)
        p = enc.psnr(r)
        trace.append({"step": step, "psnr_rgb": p, "bpp": None, "refined": True})
        if p >= target:
            res, ps = r, p
        else:
            miss = (math.log2(step), p)
    return res


def encode_tx(lf, options: EncodeOptions, progress=None) -> Encoded:
    """Encode with the ``tx`` profile (rate control for a PSNR or bpp target); the views
    that are not key views are coded where ``options.workers`` / ``options.scheduler`` say. A
    PSNR target that no lossy setting reaches gets the lossless file (a note says so). A
    per-view floor (``min_view_psnr``, without a bpp target) raises the pooled PSNR target until
    the worst view meets it (at most FLOOR_TRIES more encodes; a note says what it took)."""
    from .ratecontrol import check_targets

    check_targets(options.target_psnr, options.target_bpp)
    params = _params_from(options)
    floor = options.min_view_psnr
    if floor is not None and not 0 < floor <= 200:
        raise ParameterError(f"the per-view PSNR floor must be within 0..200 dB, got {floor!r}")
    with make_runner(options.workers, options.scheduler) as runner:
        if floor is None or params.lossless or options.target_bpp is not None or params.step is not None:
            return _encode_psnr(lf, options, params, progress, runner)
        target = min(max(options.target_psnr if options.target_psnr is not None else floor, floor, 10.0), 200.0)
        trace, seen = [], []
        for tries in range(FLOOR_TRIES + 1):
            out = _encode_psnr(lf, replace(options, target_psnr=target), params, progress, runner)
            trace += out.trace
            worst = _or_inf(out.summary["psnr_view_min"])
            if worst >= floor or tries == FLOOR_TRIES or out.summary.get("params", {}).get("lossless"):
                break
            seen.append((target, worst))
            # the worst view follows the pooled target about 1:1 at first; then by the secant
            # through the last two encodes (slope kept within 1/4 … 3/2)
            slope = 1.0 if len(seen) < 2 else (seen[-1][1] - seen[-2][1]) / (seen[-1][0] - seen[-2][0])
            target = min(target + (floor - worst + 0.05) / min(max(slope, 0.25), 1.5), 200.0)
        out.trace = trace
        if worst >= floor and target > (options.target_psnr or -math.inf) + 1e-9:
            out.notes = [f"the per-view floor of {floor:g} dB took a pooled target of {target:.2f} dB (worst view "
                         f"{worst:.2f} dB)"] + out.notes
        elif worst < floor:
            out.target_met = False
        return out


#: more encodes, each at a higher pooled target, that a per-view PSNR floor may take
FLOOR_TRIES = 3


def _or_inf(psnr: float | None) -> float:
    """A summary's PSNR (None where exact) as a number."""
    return math.inf if psnr is None else psnr


#: a size target whose search left this share of the size unspent (the finest lossy setting
#: reached, or a staircase) tries the lossless file, kept where it fits
BPP_UNSPENT = 0.1


def _encode_psnr(lf, options: EncodeOptions, params: TxParams, progress, runner) -> Encoded:
    """One encode for ``options``' target. A PSNR target that no lossy setting reaches gets the
    lossless file; so does a size target that the lossless file fits (the best quality within
    it: the search of the lossy settings stops at the finest quantizer)."""
    out = _encode_tx(lf, options, params, progress, runner)
    if (options.target_bpp is not None and not params.lossless and params.step is None
            and out.summary["psnr_rgb"] is not None
            and file_bpp(lf, out.config, out.sections) < (1 - BPP_UNSPENT) * options.target_bpp):
        exact = _encode_tx(lf, replace(options, target_bpp=None, lossless=True), replace(params, lossless=True),
                           progress, runner)
        b = file_bpp(lf, exact.config, exact.sections)
        if b <= options.target_bpp:
            exact.notes = [f"the lossless file fits within {options.target_bpp:g} bpp ({b:.3f} bpp; the finest "
                           f"lossy setting gives {out.summary['psnr_rgb']:.2f} dB): it is written"] + exact.notes
            exact.trace = out.trace + exact.trace
            exact.target_met = True
            return exact
        out.trace += exact.trace
    if options.target_psnr is not None and out.target_met is False and not params.lossless:
        # no lossy setting reaches the target (8-bit views above 50-59 dB: the finest quantizer
        # step is 1): the lossless file does, and is then the smallest file that does
        closest = out.summary["psnr_rgb"]
        exact = _encode_tx(lf, replace(options, target_psnr=None, lossless=True),
                           replace(params, lossless=True), progress, runner)
        exact.notes = [f"no lossy setting reaches {options.target_psnr:g} dB (the finest quantizer gives "
                       f"{closest:.2f} dB): the file is lossless (exact)"] + exact.notes
        exact.trace = out.trace + exact.trace
        exact.target_met = True
        return exact
    return out


def _encode_tx(lf, options: EncodeOptions, params: TxParams, progress, runner) -> Encoded:
    from .ratecontrol import depth_scale

    # a PSNR search codes a sample of the views at each pass (held once known, below); other
    # encodes code every view at each of their passes, so every view is kept once read
    sampled = (options.target_psnr is not None and params.search_sample and not params.lossless
               and params.step is None)
    reprice = ((options.target_psnr is not None or options.target_bpp is not None) and params.step is None
               and not params.lossless and "maps_reprice" not in params.ablate)
    enc = TxEncoder(lf, params, progress, side_lambda(lf, options, params), runner, hold_all=not sampled,
                    keep_luma=reprice)
    enc.keep_decoded = options.keep_decoded
    scale = depth_scale(lf.views.dtype)
    nv = lf.rows * lf.cols
    model = Model(default_counts())
    trace, notes, found = [], [], None

    def run(step):
        return enc.run(step, model, progress)

    peak = float(np.iinfo(lf.views.dtype).max)
    if params.step is not None or (options.target_psnr is None and options.target_bpp is None):
        step0 = params.step if params.step is not None else 8.0 * scale
    elif options.target_psnr is not None:       # where the target's MSE puts the step (Δ² ≈ 12·D)
        step0 = math.sqrt(12 * peak ** 2 * 10 ** (-options.target_psnr / 10))
    else:
        step0 = 8.0 * scale
    probe = None
    maps_ratio = None                         # the λ ratio the maps were repriced at, if they were
    maps_kind = None                          # … and what was: "corrections" or "modes" (and corrections)
    # a PSNR target on a grid with many views: the probe and the search code the key views and a
    # sample of the others (their errors stand for the rest; every view is independent given the
    # keys), and the chosen step is then checked on every view (below: corrected if it misses)
    others = np.flatnonzero(~enc.is_key)
    sample = others[::SEARCH_STRIDE] if sampled and others.size >= SEARCH_MIN_VIEWS else None
    # every view of a posed capture is coded in each pass of its search; a pass that only
    # measures an entropy model codes every SEARCH_STRIDE-th view
    model_sample = np.arange(0, nv, SEARCH_STRIDE) if enc.all_intra and nv >= SEARCH_MIN_VIEWS else None
    if sampled:
        enc.hold(np.arange(nv) if sample is None else np.union1d(enc.s.keys, sample))
    if params.key_ratio == 0 and not params.lossless and others.size:
        probe = enc.run(step0, model, progress, views=sample)
        enc.kr = enc.auto_key_ratio(probe)      # one probe run measures how much views inherit

    # (a first pass measures the entropy model; its codes are dropped before the pass that
    # uses the model, so the two passes' levels never exist at once)
    slope0 = PSNR_SLOPE
    j2k_only = False
    j2k_met = None
    if (lf.layout != "grid" and enc.all_intra and (options.target_psnr is not None or options.target_bpp is not None)
            and params.step is None and not params.lossless):
        # every view of a posed capture coded alone: each view's 8×8 DCT rounded to one step
        # (open loop) says how the views share the error and where the quantizer search starts
        from .j2kalloc import step_prior

        got = Runner().map_threaded(_dct_task, [(enc, v) for v in range(nv)])
        samples = [s for s, _ in got]
        smooth = max(sm for _, sm in got)
        # natural views as JPEG 2000, searched on JPEG 2000's own levels; smooth views (the
        # transform path may win at the quality reached), or a target beyond JPEG 2000's finest
        # lossy level, take the full search below (the transform path or JPEG 2000, per view)
        if enc.intra_codec == "j2k" and (options.target_psnr is None
                                         or smooth <= options.target_psnr - J2K_SMOOTH_MARGIN_DB):
            res, found = _search_j2k_levels(enc, options.target_psnr, options.target_bpp, step0, samples, trace,
                                            progress, options.min_view_psnr if options.target_bpp is None else None)
            j2k_only = options.target_psnr is not None or smooth <= enc.psnr(res) - J2K_SMOOTH_MARGIN_DB
            if found and not j2k_only:
                j2k_met = res                 # a size JPEG 2000 met: the full search must beat it
        if not (j2k_only and found) and options.target_psnr is not None:
            s_p, slope0 = step_prior(samples, np.ones(nv), float(enc.peak), options.target_psnr)
            step0 = PROXY_STEP_RATIO * s_p
        elif j2k_met is not None:
            # a size JPEG 2000 met: the full search starts at the step of the quality it reached
            # there (the transform path lands near it), not at the default step
            step0 = PROXY_STEP_RATIO * step_prior(samples, np.ones(nv), float(enc.peak), enc.psnr(j2k_met))[0]
        del got, samples
    if j2k_only and found:
        pass                                  # (that search's run is the file)
    elif params.lossless:
        measured = enc.model_of(run(1.0))
        res = enc.run(1.0, measured, progress, keep_pixels=True)
    elif options.target_psnr is None and options.target_bpp is None:
        step = params.step if params.step is not None else 8.0 * scale
        # the probe coded every view at this step: its model stands for the pass that would
        # measure one (with the key ratio the probe set, the keys' symbols shift a little)
        measured = enc.model_of(probe if probe is not None and probe["step"] == step else run(step))
        probe = None
        res = enc.run(step, measured, progress, keep_pixels=True)
    else:
        models: dict = {}                     # step → the entropy model measured there

        def evaluate(logq):
            step = 2.0 ** logq
            near = min(models, key=lambda k: abs(math.log2(k) - logq)) if models else None
            far = near is None or abs(math.log2(near) - logq) > MODEL_REACH
            use = models[near] if near is not None else model
            if far:                   # between two measured models: theirs, interpolated
                between = _between_models(models, logq)
                if between is not None:
                    use, far = between, False
            r = enc.run(step, use, progress, views=model_sample if far and model_sample is not None else sample)
            r["model_step"] = near
            if far:                   # far from any model: measure one first (on a sample of a posed capture's views)
                r = enc.run(step, enc.model_of(r), progress, views=sample)
                r["model_step"] = step
            models[step] = r["measured"] = enc.model_of(r)
            ps = enc.psnr(r)
            b = None
            if options.target_bpp is not None:
                b = file_bpp(lf, *enc.pack(r))
            trace.append({"step": step, "psnr_rgb": ps, "bpp": b, **({"views": "sample"} if sample is not None else {})})
            ok = ps >= options.target_psnr if options.target_psnr is not None else b <= options.target_bpp
            return ok, r

        lo_q, hi_q = 0.0, math.log2(512.0 * scale)
        q0 = min(max(math.log2(step0), lo_q), hi_q)
        if probe is not None:          # the probe pass says where the target lies (prior slope)
            ps0 = enc.psnr(probe)
            if options.target_psnr is not None:
                # (the probe codes with the default key ratio, before the one it sets: from it
                # the PSNR falls more slowly towards a coarser step than the search's points do,
                # and rises more slowly towards a finer one)
                shift = (options.target_psnr - ps0) / PROBE_SLOPES[0 if ps0 > options.target_psnr else 1]
                q0 = q0 + shift
            else:
                b0 = file_bpp(lf, *enc.pack(probe))
                shift = (math.log2(options.target_bpp) - math.log2(b0)) / BPP_SLOPE
                q0 = q0 + shift
            q0 = min(max(q0, lo_q), hi_q)
            models[probe["step"]] = enc.model_of(probe)   # the first evaluation's model, where near
            # the maps were estimated at the λ of the step the target's MSE suggests (step0); views
            # that predict well are coded at a much coarser one (hci_antinous at 40 dB: 41, not
            # 8.8), where λ is (41 / 8.8)² as large and corrections no longer pay their bits: the
            # prior's step shift in octaves is a λ ratio of 4 ** shift
            if reprice and enc.has_maps and 4.0 ** shift >= MAPS_REPRICE_RATIO:
                maps_ratio = 4.0 ** shift
                q0 = math.log2(enc.grid_step(2.0 ** q0))
                step = 2.0 ** q0
                maps_kind = _maps_pay_repriced(enc, step, models[probe["step"]], maps_ratio, sample, others.size,
                                               models, progress)
                if maps_kind is None:
                    maps_ratio = None
        enc.drop_luma()                # (kept for the maps' repricing only)
        probe = None                   # (its coded views are not needed any more)
        floor = options.target_psnr is not None

        def value(q):
            ok, r = evaluate(q)
            t = trace[-1]
            return (t["psnr_rgb"] if floor else math.log2(max(t["bpp"], 1e-12))), r

        def prefer(qn, rn, qo, ro):      # a floor: the largest step; a ceiling: the best quality
            return qn > qo if floor else enc.psnr(rn) >= enc.psnr(ro)

        sr = secant_search(value, q0, options.target_psnr if floor else math.log2(options.target_bpp),
                           feasible_above=floor, slope0=slope0 if floor else BPP_SLOPE, lo=lo_q, hi=hi_q,
                           tol=0.03 if floor else 0.01, prefer=prefer, min_width=SEARCH_MIN_WIDTH if floor else 1 / 64,
                           snap=lambda q: math.log2(enc.grid_step(2.0 ** q)))
        found, res = sr.found, sr.result
        restored = False                      # (the search's passes coded with other maps than the file's)
        if maps_ratio is not None and (res["step"] / step0) ** 2 < MAPS_REPRICE_RATIO:
            # the probe's prior slope put the step far coarser than the search found it (PSNR
            # falling faster with the step than the prior): the maps as estimated code the file
            enc.restore_maps()
            maps_ratio = maps_kind = None
            restored = True
        if not found:
            notes.append(FINEST_NOTE if floor else COARSEST_NOTE)
        # one more pass with the model of the chosen point, kept where it meets the target and,
        # for a bpp target, gives better quality; but a posed capture's search pass coded every
        # view (each keeping its pixels), and where its model was measured within MODEL_REACH
        # that pass is the file's as it is (mitsuba_objects_360: ±0.02% bytes, one pass in four)
        if (sample is None and enc.all_intra and res.get("model_step") is not None
                and abs(math.log2(res["model_step"] / res["step"])) <= MODEL_REACH):
            res["kept"] = True
        else:
            again = enc.run(res["step"], res.get("measured") or enc.model_of(res), progress, keep_pixels=True)
            ps = enc.psnr(again)
            if options.target_psnr is not None:
                keep = ps >= options.target_psnr
                trace.append({"step": res["step"], "psnr_rgb": ps, "bpp": None, "refined": True})
                # the search saw a sample, or coded with the repriced maps the file does not
                # carry (its pass is not the file's: a 3×3 rig's file decoded 0.03 dB below the
                # target the pass had met): the full pass decides
                if sample is not None or restored:
                    tries, miss = 0, None
                    while found and ps < options.target_psnr and tries < 4:
                        tries += 1           # below the target on all views: a finer step, by the slope
                        miss = (math.log2(res["step"]), ps)
                        if tries <= 3:
                            step = res["step"] * 2.0 ** ((options.target_psnr + 0.02 - ps) / PSNR_SLOPE)
                        else:
                            # the slope's steps were too small to move a flat PSNR (a 4×4 RGBA crop
                            # at 45 dB missed by 0.005 dB at three steps 0.6% apart, and was written
                            # lossless as if no lossy step reached it): a quarter octave finer, once
                            step = enc.grid_step(res["step"] * 2.0 ** -FALLBACK_OCTAVES)
                        again = enc.run(step, enc.model_of(again), progress, keep_pixels=True)
                        ps = enc.psnr(again)
                        trace.append({"step": step, "psnr_rgb": ps, "bpp": None, "refined": True})
                        res = again
                    found = found and ps >= options.target_psnr
                    if found and miss is not None:
                        res = _close_in(enc, res, miss, options.target_psnr, progress, trace)
                        again, ps = res, enc.psnr(res)
                    keep = True              # (the search's own run covered a sample only)
            else:
                b = file_bpp(lf, *enc.pack(again))
                keep = restored or (b <= options.target_bpp and ps >= enc.psnr(res))
                trace.append({"step": res["step"], "psnr_rgb": ps, "bpp": b, "refined": True})
            if keep:
                res = again
        if options.target_psnr is not None and found and "lambda_trim" not in params.ablate:
            res = _trim_lambda(enc, res, options.target_psnr, progress, trace)
        if j2k_met is not None and (not found or enc.psnr(j2k_met) > enc.psnr(res)):
            # the views as JPEG 2000 met the size where the search did not, or at a better quality
            if not found:
                notes.remove(COARSEST_NOTE)
            notes.append("the views as JPEG 2000 meet this size " + ("at a better quality than the transform path"
                         if found else "where the transform path cannot") + ": they are the file")
            res, found = j2k_met, True
        j2k_met = None
    promote_note = None
    if not params.lossless and enc.intra_codec == "j2k" and lf.layout == "grid" and "promote" not in params.ablate:
        res = enc.with_pixels(res)
        n_alone = len(enc.promote_views(res))
        if n_alone:
            promote_note = (f"{n_alone} views that are not key views cost less coded alone (JPEG 2000) than "
                            f"predicted; they are key views of this file")
            notes.append(promote_note)
            # (a promoted view has no more error than its transform coding: a file that missed a
            # PSNR target narrowly may meet it now, and is then no miss to replace with the
            # lossless file: a 4×4 RGBA crop at 45 dB missed by 0.006 dB, met it at 45.10 after
            # promotion, and was written lossless, 4× larger)
            if options.target_psnr is not None and not found and enc.psnr(res) >= options.target_psnr:
                found = True
                for n in (COARSEST_NOTE, FINEST_NOTE):
                    if n in notes:
                        notes.remove(n)
    if (not params.lossless and enc.intra_codec == "j2k" and lf.layout == "grid"
            and (options.target_psnr is not None or options.target_bpp is not None) and params.step is None
            and len(res["keyimg"]) >= J2K_ALL_SHARE * nv and "j2k_all" not in params.ablate):
        alone = _every_view_j2k(enc, res, options, step0, found, trace, progress)
        if alone is not None:
            res, found = alone, True
            notes = [n for n in notes if n not in (COARSEST_NOTE, FINEST_NOTE, promote_note)]
            notes.append(f"every view coded alone as JPEG 2000 makes a smaller file at the target than "
                         f"predicting views: the {nv} views are JPEG 2000 images (no view is predicted)")
    enc.hold(())
    cfg, sections = enc.pack(res)
    split = enc.key_split(res)
    if params.key_split and split != params.key_split and enc.coded_keys(res):
        notes.append(f"--key-split {params.key_split} does not divide the {enc.nbx} blocks of a row: the key rows "
                     f"are {split} streams each (the largest divisor below it)")
    if lf.layout != "grid":
        notes.append("posed capture: every view is coded on its own (no inter-view prediction), so this file is "
                     "no smaller than per-view coding (JPEG 2000 or the transform path, whichever is smaller per view)")
    return Encoded(cfg, sections, enc.decoded(res), trace, notes, found,
                   summary={"profile": "tx", "params": {**params_info(params), "step": res["step"],
                                                        "lam_scale": res.get("lam_scale", 1.0),
                                                        "key_ratio": enc.key_ratio(),
                                                        "maps_repriced": maps_ratio,
                                                        "maps_repriced_modes": maps_kind == "modes"},
                            "key_views": len(enc.structure_of(res)[0]),
                            "views_coded_alone": len(res.get("promoted", ())),
                            "views_weighted": int(weighted_views(enc.weights_of(res)).sum()),
                            **({"warps": enc.warp_report} if enc.warp_report is not None else {}),
                            "psnr_rgb": finite(enc.psnr(res)), "psnr_view_min": finite(float(enc.view_psnrs(res).min())),
                            **runner.describe()})



__all__ = ["encode_tx", "side_lambda", "file_bytes", "file_bpp"]
