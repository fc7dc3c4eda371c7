"""Coding the top-level key views as images (imagecodecs: JPEG 2000 / JPEG XL in memory).

Lossless by default (the smaller of reversible JPEG 2000 and lossless JPEG XL, per image);
lossy JPEG 2000 at a target PSNR is optional, and its decoded pixels feed the closed loop.
"""
from __future__ import annotations

import numpy as np

from formats.errors import ChecksumError, UnsupportedError

def encode_image(img: np.ndarray, codec: str = "auto", psnr: float | None = None) -> tuple[str, bytes]:
    """Encode (H, W, C) uint8/uint16 → (codec name, bytes). ``psnr`` makes JPEG 2000 lossy."""
    import imagecodecs

    a = img[..., 0] if img.shape[-1] == 1 else img
    if psnr is not None:
        return "j2k", imagecodecs.jpeg2k_encode(a, level=float(psnr))
    out = {}
    if codec in ("auto", "j2k"):
        out["j2k"] = imagecodecs.jpeg2k_encode(a, level=0, reversible=True)
    if codec in ("auto", "jxl"):
        out["jxl"] = imagecodecs.jpegxl_encode(a, lossless=True, effort=7 if a.size < 4_000_000 else 3)
    if not out:
        raise UnsupportedError(f"unknown top-level codec {codec!r} (expected auto, j2k or jxl)")
    name = min(out, key=lambda k: len(out[k]))
    return name, bytes(out[name])


def decode_image(codec: str, data: bytes, shape: tuple, dtype) -> np.ndarray:
    """Decode one top-level image and check it has the expected (H, W, C) shape and dtype."""
    import imagecodecs

    try:
        if codec == "j2k":
            img = imagecodecs.jpeg2k_decode(data)
        elif codec == "jxl":
            img = imagecodecs.jpegxl_decode(data)
        else:
            raise UnsupportedError(f"unknown top-level image codec {codec!r}")
    except imagecodecs.DelayedImportError as e:  # pragma: no cover
        raise UnsupportedError(str(e)) from None
    except Exception as e:  # imagecodecs raises its own per-codec errors
        if isinstance(e, UnsupportedError):
            raise
        raise ChecksumError(f"top-level {codec} image does not decode ({e})") from None
    img = np.asarray(img)
    if img.ndim == 2:
        img = img[:, :, None]
    if img.shape != tuple(shape) or img.dtype != np.dtype(dtype):
        raise ChecksumError(f"top-level image decodes to {img.shape} {img.dtype}, expected {tuple(shape)} {np.dtype(dtype)}")
    return img
