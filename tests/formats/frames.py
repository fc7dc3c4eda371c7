"""The check that the viewer's JavaScript renderer draws the Python renderer's frames."""
from __future__ import annotations

import numpy as np


def assert_same_frame(want: np.ndarray, got: np.ndarray, share: float = 0.001) -> None:
    """The JavaScript novel view ``got`` (H, W, C' ≤ C) is the Python renderer's ``want`` (H, W, C)
    within float rounding: both sample at the exact positions (OpenCV 5's remap), bicubically for
    the blend and bilinearly for the robust choice, so a sample differs only where float sums
    round a value across .5: at most 3 grey levels, at under ``share`` of the samples. (When the
    page rounded positions to 1/32 px and blended bilinearly, epfl_iso_chart_1's frames were
    36.6 dB and 62 grey levels apart.)"""
    c = got.shape[-1]
    e = np.abs(want[..., :c].astype(np.int64) - got.astype(np.int64))
    assert e.max() <= 3 and (e > 0).mean() < share, (int(e.max()), float((e > 0).mean()))
