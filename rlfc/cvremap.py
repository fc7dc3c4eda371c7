"""OpenCV's ``remap`` for images and maps of any size.

OpenCV addresses source and destination images below 32 767 pixels a side (``SHRT_MAX``);
the format allows wider views (up to 2^26 pixels, e.g. 16 × 65 536). Larger calls are cut into
destination tiles, each remapped from the crop of the source its map reaches (plus the
interpolation's taps). The values are the same: a crop shifts the coordinates by whole pixels,
exact in float32 and leaving each coordinate's fraction as it was (OpenCV 5 samples at the exact
fraction; OpenCV 4 rounded it to 1/32 pixel, which a whole-pixel shift keeps too), and the crop
keeps the source's own edge wherever a tap could reach it, so ``BORDER_REPLICATE`` repeats the
same pixels.
"""
from __future__ import annotations

import numpy as np

SIDE = 32766          # largest image side OpenCV's remap accepts (< SHRT_MAX)
TILE = 4096           # destination tile side of the cut path


def remap(src: np.ndarray, mapx: np.ndarray, mapy: np.ndarray, interpolation: int,
          out: np.ndarray | None = None) -> np.ndarray:
    """``cv2.remap(src, mapx, mapy, interpolation, borderMode=BORDER_REPLICATE)`` for any size
    (into ``out`` where given: an array of the result's shape and dtype).

    Args:
        src: (H, W) or (H, W, C) image. mapx, mapy: (h, w) float32 source columns and rows.
        interpolation: ``cv2.INTER_LINEAR`` or ``cv2.INTER_CUBIC``.

    Returns:
        (h, w) or (h, w, C) samples, as OpenCV returns them ((h, w) for one channel).
    """
    import cv2

    h, w = mapx.shape
    if max(src.shape[0], src.shape[1], h, w) <= SIDE:
        return cv2.remap(src, mapx, mapy, interpolation, dst=out, borderMode=cv2.BORDER_REPLICATE)
    chans = src.shape[2:] if src.ndim == 3 and src.shape[2] > 1 else ()    # (OpenCV drops one channel's axis)
    if out is None:
        out = np.empty((h, w) + chans, src.dtype)
    for y in range(0, h, TILE):
        for x in range(0, w, TILE):
            _tile(src, mapx, mapy, interpolation, out, y, min(y + TILE, h), x, min(x + TILE, w))
    return out


def _tile(src, mapx, mapy, interpolation, out, y0, y1, x0, x1) -> None:
    """Remap destination rows y0:y1 and columns x0:x1 from the source crop they reach (halved
    until that crop fits OpenCV: scattered maps reach far)."""
    import cv2

    mx, my = mapx[y0:y1, x0:x1], mapy[y0:y1, x0:x1]
    reach = 2 if interpolation == cv2.INTER_CUBIC else 1          # taps beyond floor(coordinate)
    H, W = src.shape[:2]
    lo_x, hi_x = _finite_range(mx)
    lo_y, hi_y = _finite_range(my)
    cx0 = int(min(max(np.floor(lo_x) - reach, 0), W - 1))
    cx1 = int(min(max(np.floor(hi_x) + reach + 1, 0), W - 1)) + 1
    cy0 = int(min(max(np.floor(lo_y) - reach, 0), H - 1))
    cy1 = int(min(max(np.floor(hi_y) + reach + 1, 0), H - 1)) + 1
    if (cx1 - cx0 > SIDE or cy1 - cy0 > SIDE) and (y1 - y0 > 1 or x1 - x0 > 1):
        if y1 - y0 >= x1 - x0:
            ym = (y0 + y1) // 2
            _tile(src, mapx, mapy, interpolation, out, y0, ym, x0, x1)
            _tile(src, mapx, mapy, interpolation, out, ym, y1, x0, x1)
        else:
            xm = (x0 + x1) // 2
            _tile(src, mapx, mapy, interpolation, out, y0, y1, x0, xm)
            _tile(src, mapx, mapy, interpolation, out, y0, y1, xm, x1)
        return
    crop = src[cy0:cy1, cx0:cx1]
    out[y0:y1, x0:x1] = cv2.remap(crop, mx - np.float32(cx0), my - np.float32(cy0), interpolation,
                                  borderMode=cv2.BORDER_REPLICATE).reshape(out[y0:y1, x0:x1].shape)


def _finite_range(m: np.ndarray) -> tuple[float, float]:
    """(min, max) of the finite values of ``m`` ((0, 0) where none is: OpenCV sends such
    positions to the border)."""
    f = m[np.isfinite(m)]
    return (float(f.min()), float(f.max())) if f.size else (0.0, 0.0)
