"""Encode driver shared by the BISE-family profiles (``bise``, ``dcp``): options → parameters,
rate control (the profile's own search, or the quantizer search), pack."""
from __future__ import annotations

import math

import numpy as np

from formats.codec_api import EncodeOptions, Encoded, is_real
from formats.errors import ParameterError

from ..keytree import KeyTreeEncoder
from ..params import RlfcParams, flags
from ..ratecontrol import default_quant, params_for_quant, search_quant

#: RlfcParams fields every BISE-family profile accepts; profiles add their own.
COMMON = {"block_size", "threshold", "quant", "energy", "top_codec", "top_psnr"}


def base_params(lf, options: EncodeOptions, profile: str, allowed: set, defaults: dict | None = None) -> RlfcParams:
    """RlfcParams from ``options.params`` (only keys in ``allowed``; others are errors)."""
    extra = set(options.params) - allowed
    if extra:
        bad = sorted(extra)
        raise ParameterError(f"option(s) {flags(bad)} not used by profile "
                             f"{profile!r}")
    kw = {**(defaults or {}), **{k: v for k, v in options.params.items() if v is not None}}
    kw.pop("quant", None), kw.pop("threshold", None), kw.pop("energy", None)
    return RlfcParams(profile=profile, **kw)


def fixed_quant(lf, options: EncodeOptions) -> float:
    q = options.params.get("quant")
    if options.lossless:
        if q not in (None, 1, 1.0):
            raise ParameterError(f"--lossless and --quant {q} disagree (lossless is quant 1)")
        return 1.0
    if q is None:
        return default_quant(lf.views.dtype)
    if not is_real(q) or not q >= 1:
        raise ParameterError(f"--quant must be a number >= 1 (1 = lossless), got {q!r}")
    return float(q)


def check_exclusive(options: EncodeOptions) -> None:
    given = [n for n, v in (("--target-psnr", options.target_psnr), ("--target-bpp", options.target_bpp)) if v is not None]
    if options.lossless:
        given.append("--lossless")
    if options.params.get("quant") is not None and (options.target_psnr is not None or options.target_bpp is not None):
        given.append("--quant")
    if len(given) > 1:
        raise ParameterError(f"{' and '.join(given)} cannot be combined: give one way to choose the quality")


def encode_keyfamily(lf, options: EncodeOptions, strategy, progress=None, search=None,
                     allowed: set = frozenset(), defaults: dict | None = None) -> Encoded:
    """Encode with a key-tree strategy.

    Args:
        search: the profile's rate control for targets, ``search(lf, base, options, prog) ->
            (found, encoder, params, loop result, trace)``; default: the quantizer search.
        allowed: the profile's own option names (beyond :data:`COMMON`).
    """
    check_exclusive(options)
    base = base_params(lf, options, strategy.profile, COMMON | set(allowed), defaults)
    thr, eng = options.params.get("threshold"), options.params.get("energy")
    trace, notes, found = [], [], None

    def prog(i, p, ps, b):
        if progress:
            progress("rate control", i, None)

    if options.target_psnr is not None or options.target_bpp is not None:
        if search is not None:
            found, enc, params, res, trace = search(lf, base, options, prog)
        else:
            enc = KeyTreeEncoder(lf, base, strategy)
            found, params, res, trace = search_quant(enc, base, target_psnr=options.target_psnr,
                                                     target_bpp=options.target_bpp, fixed_threshold=thr,
                                                     fixed_energy=eng, progress=prog)
        if not found:
            notes.append("the search's best end does not reach the target; the closest setting is written")
    else:
        params = params_for_quant(base, fixed_quant(lf, options), thr, eng)
        enc = KeyTreeEncoder(lf, params, strategy)
        res = enc.closed_loop(params)
    cfg, sections = enc.pack(params, res)
    out = Encoded(cfg, sections, enc.decoded_views(res), trace, notes, found,
                  summary={"profile": strategy.profile, "params": params.to_dict()})
    near = NEAR_LOSSLESS_DB + 20 * math.log10(float(np.iinfo(lf.views.dtype).max) / 255)
    if options.target_psnr is not None and found and options.target_psnr >= near:
        # near lossless, the largest step that meets the target need not be the smallest file:
        # the lossless file can be smaller (dcp on dino_crop at 70 dB: 10.21 bpp at Q 1.06,
        # 9.76 lossless), and it meets any PSNR target
        plain = {k: v for k, v in options.params.items() if k not in ("quant", "threshold", "energy", "top_psnr")}
        exact = encode_keyfamily(lf, EncodeOptions(profile=options.profile, lossless=True, params=plain), strategy,
                                 progress, None, allowed, defaults={k: v for k, v in (defaults or {}).items()
                                                                   if k != "top_psnr"})
        if sum(len(x) for _, x in exact.sections) <= sum(len(x) for _, x in sections):
            exact.notes = [f"the lossless file is smaller than the lossy settings that reach "
                           f"{options.target_psnr:g} dB: it is written"]
            exact.trace, exact.target_met = trace, True
            return exact
    return out


#: PSNR targets from here on (dB, 8-bit; 48 dB more for 16-bit) also try the lossless file and
#: keep the smaller
NEAR_LOSSLESS_DB = 55.0


def encode_with_params(lf, params: RlfcParams):
    """Encode with fixed BISE-family parameters, no rate control.

    Returns:
        (config, sections, loop result); ``loop.dec0`` holds the decoded view planes.
    """
    from . import get_profile

    enc = KeyTreeEncoder(lf, params, get_profile(params.profile).strategy(lf))
    res = enc.closed_loop(params)
    cfg, sections = enc.pack(params, res)
    return cfg, sections, res
