"""The smallest JPEG 2000 codestream of an image within an error budget (in memory, imagecodecs).

OpenJPEG's lossy ``level`` is a PSNR in dB that the codestream lands near but not on (0.3–0.45 dB
below on llff_statue, up to 2 dB below on stanford_chess at 48 dB), so the level is searched: a
first guess a little above the target, then secant steps on the measured error, then bisection
between a level that met the budget and one that did not. Each try is one encode and one decode.
"""
from __future__ import annotations

import math
from typing import Callable

import numpy as np

from .topcodec import alpha_stream, has_alpha, j2k_round_trip

#: first level asked above the target PSNR (dB), and how close two levels get before stopping
FIRST_ASK_DB = 0.3
LEVEL_TOL_DB = 0.04
MAX_TRIES = 8
#: a codestream this close (dB) inside the budget ends the search
CLOSE_DB = 0.03


def smallest_j2k(img: np.ndarray, max_sse: float, sq_error: Callable[[np.ndarray], float], target_db: float,
                 give_up_bytes: float = math.inf, hint: dict | None = None,
                 threads: int = 1, alpha: bytes | None = None) -> tuple[bytes, np.ndarray] | None:
    """The smallest codestream found whose decoded image has squared error ≤ ``max_sse``.

    Args:
        img: (H, W, C) uint8/uint16 image to code (C = 1 or 3 coded as it is; with alpha, C = 2
            or 4, the colour channels are JPEG 2000 and the alpha plane follows exactly, as
            :func:`rlfc.topcodec.encode_view_j2k` codes it: its bytes count in every size here).
        max_sse: the error budget, in the units of ``sq_error``.
        sq_error: decoded (H, W, C) image → its squared error (the caller's metric, e.g. the
            colour error over the view's own pixels).
        target_db: the PSNR that ``max_sse`` stands for (where the search starts).
        give_up_bytes: the caller's alternative: stop as soon as a codestream that misses the
            budget is this large (larger levels only grow), and return nothing this large.
        hint: where the caller keeps what an earlier search of a similar image learnt: the first
            level is asked ``hint["ask_db"]`` above the target (default FIRST_ASK_DB), and the
            offset of the level that met the budget is written back (OpenJPEG lands about the
            same distance below the level asked for the same image at nearby targets: on
            stanford_chess's intra key about 1 dB, so a first ask 0.3 dB above always missed).
        threads: OpenJPEG's own threads for each encode and decode (the same codestreams and
            pixels whatever their number, checked; a 448×448 view encodes in 22.9 ms on one,
            14.9 on two).
        alpha: the image's alpha stream where the caller has it (images with alpha; made here
            otherwise).

    Returns:
        (codestream, decoded image) or None when no try met the budget below ``give_up_bytes``.
    """
    if alpha is None:
        alpha = alpha_stream(img[..., -1]) if has_alpha(img.shape[-1]) else b""
    lo = hi = None                    # levels that missed / met the budget
    best = None
    prev = None                       # (level, dB over budget) of the previous try
    ask = target_db + (hint.get("ask_db", FIRST_ASK_DB) if hint is not None else FIRST_ASK_DB)
    met_at = None                     # the level of the codestream kept
    for _ in range(MAX_TRIES):
        data, dec = j2k_round_trip(img, min(ask, 99.0), threads, alpha)
        err = sq_error(dec)
        off = 10 * math.log10(max(err, 1e-30) / max(max_sse, 1e-30))       # dB over the budget
        if err <= max_sse:
            if best is None or len(data) < len(best[0]):
                best, met_at = (data, dec), ask
            hi = ask if hi is None else min(hi, ask)
            if off > -CLOSE_DB:
                break                     # within CLOSE_DB of the budget: close enough
        elif len(data) >= give_up_bytes or ask >= 99.0:
            break                         # every level that could meet the budget is larger still
        else:
            lo = ask if lo is None else max(lo, ask)
        if lo is not None and hi is not None and hi - lo < LEVEL_TOL_DB:
            break
        # secant on the error against the level (dB of error per dB asked, clipped), aiming a
        # little inside the budget; bisection once a level on each side is known
        slope = -1.0 if prev is None or prev[0] == ask else (off - prev[1]) / (ask - prev[0])
        slope = min(max(slope, -2.0), -0.25)
        prev = (ask, off)
        nxt = ask - (off + 0.02) / slope
        if lo is not None and hi is not None and not lo < nxt < hi:
            nxt = (lo + hi) / 2
        ask = nxt
    if hint is not None and met_at is not None:
        hint["ask_db"] = met_at - target_db
    return best if best is not None and len(best[0]) < give_up_bytes else None
