"""Pixel conventions shared by every codec: sample peaks and lossless YCoCg-R planes.

Channel layouts (last axis): 1 = Y (grey), 2 = Y + A, 3 = RGB → Y Co Cg, 4 = RGBA → Y Co Cg A.
Y keeps the input's bit depth; Co and Cg need one extra bit (signed). All planes are int32.
The integer transforms are written once for numpy and torch arrays (same operators).
"""
from __future__ import annotations

import threading

import numpy as np


def peak_of(dtype) -> float:
    """Peak sample value for PSNR: 255 (uint8), 65535 (uint16), 1.0 (float)."""
    return {np.dtype(np.uint8): 255.0, np.dtype(np.uint16): 65535.0}.get(np.dtype(dtype), 1.0)


def _stack(parts, like):
    if isinstance(like, np.ndarray):
        return np.stack(parts, axis=-1)
    import torch

    return torch.stack(parts, -1)


def forward_int(x):
    """YCoCg-R forward on integer arrays of numpy or torch: (…, C) → (…, C) planes."""
    c = x.shape[-1]
    if c < 3:
        return x
    r, g, b = x[..., 0], x[..., 1], x[..., 2]
    co = r - b
    t = b + (co >> 1)
    cg = g - t
    y = t + (cg >> 1)
    return _stack([y, co, cg] + ([x[..., 3]] if c == 4 else []), x)


def inverse_int(p):
    """YCoCg-R inverse on integer arrays of numpy or torch (no clipping)."""
    if p.shape[-1] < 3:
        return p
    y, co, cg = p[..., 0], p[..., 1], p[..., 2]
    if isinstance(p, np.ndarray):                       # numpy: into one output, no stack
        out = np.empty_like(p)
        t = y - (cg >> 1)
        np.add(cg, t, out=out[..., 1])
        np.subtract(t, co >> 1, out=out[..., 2])
        np.add(out[..., 2], co, out=out[..., 0])
        if p.shape[-1] == 4:
            out[..., 3] = p[..., 3]
        return out
    t = y - (cg >> 1)
    g = cg + t
    b = t - (co >> 1)
    r = b + co
    return _stack([r, g, b] + ([p[..., 3]] if p.shape[-1] == 4 else []), p)


def to_planes(x: np.ndarray) -> np.ndarray:
    """(…, C) uint8/uint16 → (…, C) int32 planes (YCoCg-R for RGB; grey and alpha pass through)."""
    if (x.ndim >= 3 and x.shape[-1] in (3, 4) and x.dtype in (np.uint8, np.uint16) and x.size >= SPLIT_MIN
            and x.flags.c_contiguous):
        return _to_planes_split(x)
    return forward_int(x.astype(np.int32))


def _to_planes_split(x: np.ndarray) -> np.ndarray:
    """:func:`to_planes` of many samples: channels split by OpenCV, the lifting steps in place on
    contiguous int32 planes, merged back (the same integers; 0.43 ms against 0.80 for a 512² RGB
    view, measured)."""
    import cv2

    planes = [p.astype(np.int32) for p in cv2.split(x.reshape(-1, x.shape[-2], x.shape[-1]))]
    r, g, b = planes[:3]
    co = np.subtract(r, b, out=r)
    b += co >> 1                                  # t = b + (co >> 1)
    cg = np.subtract(g, b, out=g)
    b += cg >> 1                                  # y = t + (cg >> 1)
    return cv2.merge([b, co, cg] + planes[3:]).reshape(x.shape)


def luma_of(x: np.ndarray) -> np.ndarray:
    """(…, C) uint8/uint16 → (…) the Y plane of :func:`to_planes`, in ``x``'s dtype (Y keeps the
    input's range): the grey channel for 1-2 channels; for RGB(A) the lifting steps of Y only, on
    channels split by OpenCV, in int16 for 8-bit samples (Co, Cg need 9 bits) and int32 for
    16-bit ones (a 512² RGB view: 0.4 ms against 1.1 ms for every plane, then Y taken)."""
    if x.shape[-1] < 3:
        return np.ascontiguousarray(x[..., 0])
    if x.dtype not in (np.uint8, np.uint16) or not x.flags.c_contiguous or x.ndim < 3:
        return to_planes(x)[..., 0].astype(x.dtype)
    import cv2

    work = np.int16 if x.dtype == np.uint8 else np.int32
    r, g, b = (q.astype(work) for q in cv2.split(x.reshape(-1, x.shape[-2], x.shape[-1]))[:3])
    co = np.subtract(r, b, out=r)
    co >>= 1
    b += co                                       # t = b + (co >> 1)
    cg = np.subtract(g, b, out=g)
    cg >>= 1
    b += cg                                       # y = t + (cg >> 1), in [0, peak]
    return b.astype(x.dtype).reshape(x.shape[:-1])


#: samples from which :func:`from_planes` works on planes split by OpenCV (below: fewer calls win),
#: and the samples of one chunk of that path (its temporaries stay in the caches)
SPLIT_MIN = 1 << 16
SPLIT_CHUNK = 1 << 18


def from_planes(p: np.ndarray, dtype=np.uint8) -> np.ndarray:
    """Inverse of :func:`to_planes`, clipped to the range of ``dtype`` (uint8 or uint16)."""
    peak = 65535 if dtype is np.uint16 or np.dtype(dtype) == np.uint16 else 255
    p = np.asarray(p, dtype=np.int32)
    if p.ndim >= 2 and p.shape[-1] in (3, 4) and p.size >= SPLIT_MIN:
        return _from_planes_split(p, peak, dtype)
    x = inverse_int(p)
    return np.minimum(np.maximum(x, 0, out=x), peak, out=x).astype(dtype)     # ufuncs: np.clip costs µs


_SCRATCH = threading.local()      # .planes: this thread's int32 planes for the split paths


def _scratch_planes(n: int, samples: int) -> list[np.ndarray]:
    """``n`` contiguous int32 planes of ``samples`` each, kept per thread from call to call.

    The split paths' planes were fresh arrays for each row chunk: a few hundred KiB each, which
    glibc maps and unmaps around every chunk (its defaults), so every 4 KiB was a page fault on
    first write. OpenCV splitting a 512² RGB view's int32 planes took 1.4-4.2 ms into fresh
    arrays and 0.3 ms into these (measured, BENCHMARKS.md)."""
    got = getattr(_SCRATCH, "planes", None)
    if got is None or len(got) < n or got[0].size < samples:
        got = [np.empty(max(samples, SPLIT_CHUNK // 3 + 1), np.int32) for _ in range(max(n, 5))]
        _SCRATCH.planes = got
    return got


def cv_saturating_depth(dtype, peak: int) -> int | None:
    """The OpenCV depth whose saturating conversion clips integer sums to [0, ``peak``] and casts
    them to ``dtype`` in one call (uint8 / uint16 where ``peak`` is the type's largest value),
    or None (then clip and cast with numpy)."""
    import cv2

    depth = {np.dtype(np.uint8): cv2.CV_8U, np.dtype(np.uint16): cv2.CV_16U}.get(np.dtype(dtype))
    return None if depth is None or peak != np.iinfo(dtype).max else depth


def _from_planes_split(p: np.ndarray, peak: int, dtype) -> np.ndarray:
    """:func:`from_planes` of many samples: the interleaved planes split into contiguous ones
    (OpenCV), YCoCg-R inverted in place, each clipped and narrowed, then interleaved again, in
    row chunks of about SPLIT_CHUNK samples (temporaries that stay in the caches, in planes kept
    per thread); 0.64-0.76x the time of the same integer steps on strided channel views,
    measured."""
    import cv2

    C = p.shape[-1]
    if p.flags.c_contiguous:
        img = p.reshape(-1, p.shape[-2] if p.ndim >= 3 else 1, C)
    elif p.ndim == 3 and p.strides[-1] == p.itemsize and p.strides[-2] == C * p.itemsize:
        img = p                                            # rows with a stride (a cropped view): as is
    elif p.ndim == 4:                                      # views cropped from padded planes
        out = np.empty(p.shape, dtype)
        for i in range(p.shape[0]):
            out[i] = _from_planes_split(p[i], peak, dtype)
        return out
    else:
        img = np.ascontiguousarray(p).reshape(-1, p.shape[-2] if p.ndim >= 3 else 1, C)
    out = np.empty(img.shape, dtype)
    # the last sum of each colour and its clip to [0, peak] in one OpenCV call: integer sums
    # saturated to the output depth (0.8x the time of the sums, then max(0) and a saturating
    # cast, measured; the same integers)
    depth = cv_saturating_depth(dtype, peak)
    if depth is None:
        def sat_add(q, r):
            q = np.add(q, r) if r is not None else q
            return np.minimum(np.maximum(q, 0, out=q), peak, out=q).astype(dtype)
    else:
        def sat_add(q, r):
            return cv2.add(q, r if r is not None else 0, dtype=depth)
    W = img.shape[1]
    step = max(1, SPLIT_CHUNK // (W * C))
    scratch = _scratch_planes(C + 1, min(step, img.shape[0]) * W)
    for a in range(0, img.shape[0], step):
        src = img[a:a + step]
        k = src.shape[0] * W
        planes = cv2.split(src, [q[:k].reshape(src.shape[0], W) for q in scratch[:C]])
        y, co, cg = planes[:3]
        h = np.right_shift(cg, 1, out=scratch[C][:k].reshape(y.shape))
        t = np.subtract(y, h, out=y)                 # t = Y − (Cg >> 1)
        g = sat_add(cg, t)                           # G = Cg + t
        np.right_shift(co, 1, out=h)
        b = np.subtract(t, h, out=t)                 # B = t − (Co >> 1)
        rgb = [sat_add(b, co), g, sat_add(b, None)] + [sat_add(q, None) for q in planes[3:]]   # R = B + Co
        dst = out[a:a + step]
        got = cv2.merge(rgb, dst=dst)
        if not np.shares_memory(got, dst):           # (OpenCV allocated its own output)
            dst[...] = got.reshape(dst.shape)
    return out.reshape(p.shape)


def plane_weights(channels: int) -> np.ndarray:
    """Weights of the planes in PSNR_YCoCg / block energy: (6·Y + Co + Cg)/8; alpha like Y."""
    return {1: np.array([1.0]), 2: np.array([1.0, 1.0]), 3: np.array([6, 1, 1]) / 8.0,
            4: np.array([6, 1, 1, 8]) / 8.0}[channels]


def rgb_mse_weights(channels: int) -> np.ndarray:
    """How much an error of 1 in each plane adds to the mean squared error over the colour
    channels (per pixel): YCoCg-R gives MSE_RGB = eY² + eCo²/6 + eCg²/4; alpha is not colour
    (weight 0); grey is Y alone."""
    return {1: np.array([1.0]), 2: np.array([1.0, 0.0]), 3: np.array([1.0, 1 / 6, 1 / 4]),
            4: np.array([1.0, 1 / 6, 1 / 4, 0.0])}[channels]
