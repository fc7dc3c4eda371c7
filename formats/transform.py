"""Light-field transforms used before coding (e.g. training an LFN at reduced resolution)."""
from __future__ import annotations

import numpy as np

from .lightfield import LightField


def resize_lightfield(lf: LightField, long_side: int) -> LightField:
    """Area-downsample every view so the long side is ``long_side`` px; intrinsics follow."""
    import cv2

    h, w = lf.height, lf.width
    s = long_side / max(h, w)
    if s >= 1:
        return lf
    nh, nw = max(1, round(h * s)), max(1, round(w * s))
    flat = lf.views.reshape(-1, h, w, lf.channels)
    out = np.stack([cv2.resize(v, (nw, nh), interpolation=cv2.INTER_AREA).reshape(nh, nw, lf.channels) for v in flat])
    sx, sy = nw / w, nh / h
    return LightField(views=out.reshape(lf.rows, lf.cols, nh, nw, lf.channels), positions=lf.positions, c2w=lf.c2w,
                      focal=(lf.focal[0] * sx, lf.focal[1] * sy),
                      principal=(lf.principal[0] * sx, lf.principal[1] * sy), layout=lf.layout,
                      meta={**lf.meta, "resized_from": [h, w]})
