"""Coding the top-level key views as images (imagecodecs: JPEG 2000 / JPEG XL in memory).

Lossless by default (the smaller of reversible JPEG 2000 and lossless JPEG XL, per image);
lossy JPEG 2000 at a target PSNR is optional, and its decoded pixels feed the closed loop.
"""
from __future__ import annotations

import numpy as np

from formats.errors import ChecksumError, FormatError, UnsupportedError


def has_alpha(channels: int) -> bool:
    """Whether views of ``channels`` channels carry alpha (grey + alpha, RGBA)."""
    return channels in (2, 4)


def alpha_stream(alpha: np.ndarray) -> bytes:
    """A view's alpha plane, exactly: zlib (level 9) of its (H, W) samples, raster order, in
    the view's dtype, little-endian. On mitsuba_objects_360 (100 × 256² masks with soft edges)
    this is 1 416 B a view, smaller than PNG (1 882), JPEG-LS (1 623) or reversible JPEG 2000
    (4 978); only lossless JPEG XL (957) was smaller, at 36 ms a view against 4 ms."""
    import zlib

    a = np.ascontiguousarray(alpha, alpha.dtype.newbyteorder("<"))
    return zlib.compress(a.tobytes(), 9)


def read_alpha(data, height: int, width: int, dtype, what: str) -> np.ndarray:
    """(height, width) alpha samples of :func:`alpha_stream` bytes; the stream must hold exactly
    that many samples (its size is checked while inflating, before anything is allocated for it).

    Raises:
        FormatError: not a zlib stream, or not exactly height × width samples.
    """
    from .txsections import inflate

    dt = np.dtype(dtype).newbyteorder("<")
    n = height * width * dt.itemsize
    raw = inflate(data, n, what)
    if len(raw) != n:
        raise FormatError(f"{what} holds {len(raw)} bytes of alpha, expected {n}")
    return np.frombuffer(raw, dt).astype(np.dtype(dtype)).reshape(height, width)


def encode_view_j2k(img: np.ndarray, level: float, threads: int = 1, alpha: bytes | None = None) -> bytes:
    """One view as an image entry of ``tx.keyimg``: a JPEG 2000 codestream (OpenJPEG quality
    ``level``, dB) of its colour channels, followed, for views with alpha, by the alpha plane's
    :func:`alpha_stream` (``alpha``: those bytes where the caller has them already).

    Args:
        img: (H, W, C) uint8/uint16 view, C = 1 to 4.
    """
    import imagecodecs

    C = img.shape[-1]
    col = img[..., :C - 1] if has_alpha(C) else img
    data = bytes(imagecodecs.jpeg2k_encode(col[..., 0] if col.shape[-1] == 1 else col, level=float(level),
                                           codecformat="J2K", numthreads=threads))
    if has_alpha(C):
        data += alpha if alpha is not None else alpha_stream(img[..., -1])
    return data


def decode_view_j2k(data, shape: tuple, dtype, alpha_bytes: int = 0, threads: int = 1,
                    alpha: np.ndarray | None = None, what: str = "a view") -> np.ndarray:
    """(H, W, C) pixels of an image entry of :func:`encode_view_j2k`: where the views carry
    alpha (C = 2 or 4) the entry's last ``alpha_bytes`` bytes are its alpha stream, and the
    JPEG 2000 codestream before them holds C − 1 components (``alpha``: the (H, W) plane where
    the caller knows it, an encoder, which then passes ``alpha_bytes`` = its stream's length;
    ``what``: the view, as errors name it).

    Raises:
        ChecksumError / FormatError: a codestream or alpha stream that does not decode to the shape.
    """
    H, W, C = shape
    if not has_alpha(C):
        return decode_image("j2k", data, shape, dtype, threads=threads)
    if not 0 < alpha_bytes < len(data):
        raise FormatError(f"{what}: an image entry of {len(data)} bytes cannot end in an alpha stream of {alpha_bytes}")
    cut = len(data) - alpha_bytes
    col = decode_image("j2k", data[:cut], (H, W, C - 1), dtype, threads=threads)
    if alpha is None:
        alpha = read_alpha(data[cut:], H, W, dtype, f"{what}'s alpha stream")
    out = np.empty((H, W, C), np.dtype(dtype))
    out[..., :C - 1] = col
    out[..., C - 1] = alpha
    return out


def j2k_round_trip(img: np.ndarray, level: float, threads: int = 1, alpha: bytes = b"") -> tuple[bytes, np.ndarray]:
    """An encoder's trial of one view as JPEG 2000: (its image entry, :func:`encode_view_j2k` at
    OpenJPEG quality ``level``, and the (H, W, C) pixels it decodes to). ``alpha``: the view's
    alpha stream (views with alpha; b"" otherwise): its alpha plane is ``img``'s own, exact."""
    data = encode_view_j2k(img, level, threads, alpha)
    return data, decode_view_j2k(data, img.shape, img.dtype, len(alpha), threads, img[..., -1] if alpha else None)


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


def j2k_size(data: bytes) -> tuple[int, int, int]:
    """(height, width, components) from a JPEG 2000 codestream's SIZ marker, read before
    decoding (so a crafted stream cannot drive a huge allocation).

    Raises:
        ChecksumError: not a codestream starting SOC, SIZ.
    """
    b = bytes(data[:96])
    if b[:4] == b"\xff\x4f\xff\x51" and len(b) >= 42:          # codestream: SOC then SIZ
        xsiz, ysiz, xo, yo = (int.from_bytes(b[8 + 4 * i:12 + 4 * i], "big") for i in range(4))
        return ysiz - yo, xsiz - xo, int.from_bytes(b[40:42], "big")
    i = b.find(b"ihdr")
    if b[4:8] == b"jP  " and i >= 0 and len(b) >= i + 14:          # JP2 file: the ihdr box
        h, w = int.from_bytes(b[i + 4:i + 8], "big"), int.from_bytes(b[i + 8:i + 12], "big")
        return h, w, int.from_bytes(b[i + 12:i + 14], "big")
    raise ChecksumError("image is not a JPEG 2000 codestream or JP2 file")


def decode_image(codec: str, data: bytes, shape: tuple, dtype, threads: int = 1) -> np.ndarray:
    """Decode one top-level image and check it has the expected (H, W, C) shape and dtype
    (for JPEG 2000 the declared size is checked before decoding). ``threads``: the codec's own
    threads (OpenJPEG decodes code-blocks in parallel: a 432×512 key view at 2 bpp took 19.9 ms
    on one thread, 12.0 on two, measured; the same pixels)."""
    import imagecodecs

    if codec == "j2k" and j2k_size(data) != tuple(shape):
        raise ChecksumError(f"top-level j2k image declares {j2k_size(data)} (H, W, C), expected {tuple(shape)}")

    try:
        if codec == "j2k":
            img = imagecodecs.jpeg2k_decode(data, numthreads=threads)
        elif codec == "jxl":
            img = imagecodecs.jpegxl_decode(data, numthreads=threads)
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
