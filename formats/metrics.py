"""Quality and rate metrics, one definition everywhere (CLI --json, tests, benchmarks).

- bpp = 8 × file bytes / (views × H × W): bits per pixel of a view, all channels together.
- Colour channels: RGB (3 or 4 channels) or the grey channel (1 or 2); alpha is never pooled
  with colour.
- PSNR_RGB = 10·log10(peak² / MSE), MSE pooled over all views, pixels and colour channels;
  peak = 255 (8-bit), 65535 (16-bit), 1.0 (float). Per-view PSNRs use each view's own MSE.
- PSNR over visible pixels (RGBA / grey+alpha): the same MSE restricted to pixels whose
  reference alpha is > 0.
- Alpha: reported apart, as exact (bool) and its own PSNR.
- PSNR_YCoCg = (6·PSNR_Y + PSNR_Co + PSNR_Cg) / 8 on the YCoCg-R planes, same peak
  (grey input: PSNR_Y).
- SSIM = scikit-image's structural_similarity per view on the colour channels
  (channel_axis=-1, data_range=peak: uniform 7×7 window), averaged over views; computed with
  OpenCV box filters (the same value to ~1e-14, tested against scikit-image).
"""
from __future__ import annotations

import math

import numpy as np

from .errors import ParameterError
from .pixels import peak_of, to_planes

__all__ = ["peak_of", "mse", "psnr_rgb", "psnr_views", "psnr_visible", "psnr_alpha", "psnr_ycocg", "ssim", "ssim_image", "bpp",
           "colour_channels", "quality_report", "QualityAccumulator", "views_per_chunk", "finite", "colour_sq_error", "psnr_from_sq_error"]


def colour_channels(c: int) -> slice:
    """The colour channels of a C-channel image: RGB for 3/4, grey for 1/2."""
    return slice(0, 3) if c >= 3 else slice(0, 1)


def _flat(a: np.ndarray) -> np.ndarray:
    return a.reshape(-1, *a.shape[-3:]) if a.ndim > 3 else a[None]


def _pair(ref, dec) -> tuple[np.ndarray, np.ndarray]:
    """ref and dec as arrays of views of one size (..., H, W, C) with pixels (leading axes may
    differ: a grid against a stack), and one depth where both are unsigned (a uint8 reference
    against uint16 pixels has no one peak): else a ParameterError, not numpy's reshape error or
    a figure on the wrong scale."""
    from .errors import ParameterError

    ref, dec = np.asarray(ref), np.asarray(dec)
    if ref.ndim < 3 or ref.shape[-3:] != dec.shape[-3:] or ref.size != dec.size:
        raise ParameterError(f"metrics compare views of one shape (..., H, W, C): got {ref.shape} and {dec.shape}")
    if ref.size == 0:
        raise ParameterError(f"metrics need pixels: got views of shape {ref.shape}")
    if ref.dtype.kind == dec.dtype.kind == "u" and ref.dtype != dec.dtype:
        raise ParameterError(f"metrics compare samples of one depth: got {ref.dtype} and {dec.dtype}")
    return ref, dec


def _psnr_from_mse(m: float, peak: float) -> float:
    return float("inf") if m == 0 else 10.0 * math.log10(peak * peak / m)


#: elements of the views a metric converts to float64 at once (16 MiB): whole light fields
#: are measured a few views at a time, so a metric never holds a float copy of them
CHUNK_ELEMENTS = 1 << 21


def views_per_chunk(view_elements: int) -> int:
    """Views of ``view_elements`` samples each that a metric converts to float64 at once."""
    return max(1, CHUNK_ELEMENTS // max(int(view_elements), 1))


#: elements of one view converted at once where a metric measures views one by one (1 MiB of
#: float64): an encoder measuring each view it codes on a few threads holds no float copy of a view
BAND_ELEMENTS = 1 << 17


#: OpenCV's L2² norm of 8-bit differences (35× numpy's float64 passes on a 512×512 RGB view) sums
#: in double (4·10⁻⁹ off the integer on a 37×23 RGB view), so it is taken band by band and each band's
#: sum rounded (below). 16-bit views take numpy's path (a band's sum could reach 2^49 there).
#: Views of 2^31 samples or more do too (OpenCV's int sizes).
NORM_MAX_ELEMENTS = 1 << 31


def _exact_norm(r: np.ndarray, d: np.ndarray) -> bool:
    """Whether OpenCV's L2² norm gives ``r``'s and ``d``'s per-view sums exactly and fast:
    8-bit views, each C-contiguous (a colour slice of RGBA views is not), of at most 4 channels
    (OpenCV's image channels), fewer than NORM_MAX_ELEMENTS samples and rows of at most
    BAND_ELEMENTS samples (the bands the sums are rounded over)."""
    return (r.dtype == np.uint8 and d.dtype == np.uint8 and r.ndim == 4 and 1 <= r.shape[-1] <= 4
            and r[0].size < NORM_MAX_ELEMENTS and r.shape[2] * r.shape[3] <= BAND_ELEMENTS
            and r.flags.c_contiguous and d.flags.c_contiguous)


def _sq_err_per_view(ref: np.ndarray, dec: np.ndarray, mask: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(per-view sum of squared errors, per-view element count), float64, a few views at a time
    (a view larger than :data:`BAND_ELEMENTS`, where one view is measured at a time, in bands
    of rows: the sums of integer squares below 2^53 are exact in either order)."""
    r, d = _flat(ref), _flat(dec).reshape(_flat(ref).shape)
    sse = np.zeros(r.shape[0])
    cnt = np.zeros(r.shape[0])
    if mask is None and _exact_norm(r, d):
        import cv2

        rows = max(1, BAND_ELEMENTS // (r.shape[2] * r.shape[3]))
        for i in range(r.shape[0]):
            # each band's sum rounded: OpenCV accumulates in double, within 0.12 of the integer
            # for a band of BAND_ELEMENTS samples (N·ε·Σ, Σ ≤ N·255²), so the rounding is exact
            sse[i] = sum(round(cv2.norm(r[i, a:a + rows], d[i, a:a + rows], cv2.NORM_L2SQR))
                         for a in range(0, r.shape[1], rows))
        cnt[:] = np.prod(r.shape[1:])
        return sse, cnt
    k = views_per_chunk(np.prod(r.shape[1:]))
    if mask is None and k == 1 and r.shape[0] == 1 and r[0].size > BAND_ELEMENTS:
        rows = max(1, BAND_ELEMENTS // (r.shape[2] * r.shape[3]))
        total = 0.0
        for a in range(0, r.shape[1], rows):
            e = r[0, a:a + rows].astype(np.float64)
            e -= d[0, a:a + rows]
            e *= e
            total += float(e.sum())
        sse[0], cnt[0] = total, r[0].size
        return sse, cnt
    for i in range(0, r.shape[0], k):
        e = r[i:i + k].astype(np.float64)
        e -= d[i:i + k]
        e *= e
        if mask is not None:
            m = mask[i:i + k][..., None]
            e *= m
            cnt[i:i + k] = m.sum(axis=(1, 2, 3)) * r.shape[-1]
        else:
            cnt[i:i + k] = np.prod(r.shape[1:])
        sse[i:i + k] = e.sum(axis=(1, 2, 3))
    return sse, cnt


def colour_sq_error(ref: np.ndarray, dec: np.ndarray) -> tuple[float, float]:
    """(sum of squared errors, element count) over the colour channels of one or more views:
    summed over views, the numbers :func:`psnr_rgb` pools (so a caller that codes views one at a
    time reaches exactly the PSNR of the whole light field)."""
    ref, dec = _pair(ref, dec)
    cs = colour_channels(ref.shape[-1])
    sse, cnt = _sq_err_per_view(ref[..., cs], dec[..., cs])
    return float(sse.sum()), float(cnt.sum())


def psnr_from_sq_error(sse: np.ndarray, cnt: np.ndarray, peak: float) -> float:
    """PSNR (dB) from per-view (sum of squared errors, count), pooled as :func:`psnr_rgb` does."""
    return _psnr_from_mse(float(np.asarray(sse, np.float64).sum() / np.asarray(cnt, np.float64).sum()), peak)


def mse(ref: np.ndarray, dec: np.ndarray) -> float:
    """Mean squared error pooled over every element given (all channels), in float64."""
    ref, dec = _pair(ref, dec)
    sse, cnt = _sq_err_per_view(ref, dec)
    return float(sse.sum() / cnt.sum())


def psnr_rgb(ref: np.ndarray, dec: np.ndarray, peak: float | None = None) -> float:
    """PSNR over all views, pixels and colour channels (alpha excluded), dB; inf when identical."""
    ref, dec = _pair(ref, dec)
    cs = colour_channels(ref.shape[-1])
    return _psnr_from_mse(mse(ref[..., cs], dec[..., cs]), peak or peak_of(ref.dtype))


def psnr_views(ref: np.ndarray, dec: np.ndarray, peak: float | None = None) -> np.ndarray:
    """(N,) PSNR of each view over its colour channels (inf where a view is exact)."""
    ref, dec = _pair(ref, dec)
    cs = colour_channels(ref.shape[-1])
    sse, cnt = _sq_err_per_view(ref[..., cs], dec[..., cs])
    peak = peak or peak_of(ref.dtype)
    return np.array([_psnr_from_mse(s / n, peak) for s, n in zip(sse, cnt)])


def psnr_visible(ref: np.ndarray, dec: np.ndarray, peak: float | None = None) -> float | None:
    """Colour PSNR over pixels whose reference alpha is > 0 (None without alpha or visible pixels)."""
    ref, dec = _pair(ref, dec)
    c = ref.shape[-1]
    if c not in (2, 4):
        return None
    cs = colour_channels(c)
    mask = _flat(ref)[..., -1] > 0
    if not mask.any():
        return None
    sse, cnt = _sq_err_per_view(ref[..., cs], dec[..., cs], mask)
    return _psnr_from_mse(float(sse.sum() / cnt.sum()), peak or peak_of(ref.dtype))


def psnr_alpha(ref: np.ndarray, dec: np.ndarray, peak: float | None = None) -> float | None:
    """PSNR of the alpha channel alone (None without alpha; inf when exact)."""
    ref, dec = _pair(ref, dec)
    if ref.shape[-1] not in (2, 4):
        return None
    return _psnr_from_mse(mse(ref[..., -1:], dec[..., -1:]), peak or peak_of(ref.dtype))


def psnr_ycocg(ref: np.ndarray, dec: np.ndarray, peak: float | None = None) -> float:
    """The RLFC paper's weighted PSNR (6·Y + Co + Cg)/8 on YCoCg-R planes (grey: Y only)."""
    ref, dec = _pair(ref, dec)
    peak = peak or peak_of(ref.dtype)
    if ref.shape[-1] in (1, 2):
        return psnr_rgb(ref[..., :1], dec[..., :1], peak)
    sums = np.zeros(3)
    flat_r = _flat(ref)
    flat_d = _flat(dec).reshape(flat_r.shape)
    k = views_per_chunk(np.prod(flat_r.shape[1:3]) * 3)
    for i in range(0, flat_r.shape[0], k):
        d = (to_planes(flat_r[i:i + k, ..., :3]) - to_planes(flat_d[i:i + k, ..., :3])).astype(np.float64)
        d *= d
        sums += d.reshape(-1, 3).sum(0)
    return _ycocg_psnr(sums, flat_r[..., 0].size, peak)


def _ycocg_psnr(sums: np.ndarray, n: int, peak: float) -> float:
    """(6·PSNR_Y + PSNR_Co + PSNR_Cg) / 8 from the planes' summed squared errors over ``n``
    pixels (an exact plane counts 200 dB beside inexact ones; all exact: inf)."""
    ps = [_psnr_from_mse(s / n, peak) for s in sums]
    if any(math.isinf(p) for p in ps):
        if all(math.isinf(p) for p in ps):
            return float("inf")
        return (6 * min(ps[0], 200) + min(ps[1], 200) + min(ps[2], 200)) / 8
    return (6 * ps[0] + ps[1] + ps[2]) / 8


#: SSIM's window side (scikit-image's default: a uniform 7×7 window)
SSIM_WIN = 7


def ssim_image(a: np.ndarray, b: np.ndarray, peak: float) -> float:
    """SSIM of one (H, W, C) pair of images, both sides at least :data:`SSIM_WIN`: scikit-image's
    ``structural_similarity(a, b, channel_axis=-1, data_range=peak)`` (uniform 7×7 window,
    sample covariance, K1 = 0.01, K2 = 0.03, the window's half-width cropped from each border,
    in float32 where both images are float16/32, else float64), computed with OpenCV's box
    filter and in-place arithmetic: the same value to ~1e-14 (float32: ~1e-7), 3–4× faster."""
    import cv2

    small = (np.float16, np.float32)
    ft = np.float32 if a.dtype in small and b.dtype in small else np.float64
    if a.shape[-1] == 1:                                   # (OpenCV drops a single channel's axis)
        a, b = a[..., 0], b[..., 0]
    x, y = a.astype(ft), b.astype(ft)

    def box(src, out=None):
        return cv2.boxFilter(src, -1, (SSIM_WIN, SSIM_WIN), dst=out, normalize=True, borderType=cv2.BORDER_REFLECT)

    ux, uy = box(x), box(y)
    t = np.multiply(x, x)
    vx = box(t)
    vy = box(np.multiply(y, y, out=t))
    vxy = box(np.multiply(x, y, out=t), out=x)             # (x is not needed again)
    cov = ft(SSIM_WIN ** 2 / (SSIM_WIN ** 2 - 1))          # sample covariance
    for v, p, q in ((vx, ux, ux), (vy, uy, uy), (vxy, ux, uy)):
        v -= np.multiply(p, q, out=t)
        v *= cov
    c1, c2 = ft((0.01 * peak) ** 2), ft((0.03 * peak) ** 2)
    a1 = np.multiply(ux, uy, out=t)                        # 2·ux·uy + C1
    a1 *= 2
    a1 += c1
    b1 = np.multiply(ux, ux, out=ux)                       # ux² + uy² + C1
    b1 += np.multiply(uy, uy, out=uy)
    b1 += c1
    vxy *= 2                                               # 2·vxy + C2
    vxy += c2
    vx += vy                                               # vx + vy + C2
    vx += c2
    a1 *= vxy
    b1 *= vx
    a1 /= b1
    h = (SSIM_WIN - 1) // 2
    return float(a1[h:-h, h:-h].mean(dtype=np.float64))


def ssim(ref: np.ndarray, dec: np.ndarray, peak: float | None = None) -> float:
    """Mean SSIM over views of the colour channels (scikit-image's definition, channel_axis=-1,
    data_range=peak; :func:`ssim_image`), views on a few threads (OpenCV and numpy release the
    GIL). A view smaller than the 7×7 window counts 1 where it is exact, else 0."""
    ref, dec = _pair(ref, dec)
    return float(np.mean(_ssim_views(ref, dec, peak or peak_of(ref.dtype))))


def _ssim_views(ref: np.ndarray, dec: np.ndarray, peak: float, threads: int | None = None) -> list:
    """[SSIM of each view] (:func:`ssim`'s terms), views on ``threads`` threads (None: a few)."""
    from concurrent.futures import ThreadPoolExecutor

    from .parallel import LOCAL_THREADS

    cs = colour_channels(ref.shape[-1])
    r = _flat(ref)[..., cs]
    d = _flat(dec).reshape(_flat(ref).shape)[..., cs]

    def one(i):
        a, b = r[i], d[i]
        return ssim_image(a, b, peak) if min(a.shape[:2]) >= SSIM_WIN else float(np.all(a == b))

    n = max(1, min(LOCAL_THREADS if threads is None else threads, r.shape[0]))
    if n == 1:
        return [one(i) for i in range(r.shape[0])]
    with ThreadPoolExecutor(n) as pool:
        return list(pool.map(one, range(r.shape[0])))


def bpp(nbytes: int, n_views: int, height: int, width: int) -> float:
    """Bits per pixel of a view: 8 × bytes / (views × H × W)."""
    return 8.0 * nbytes / (n_views * height * width)


def finite(x):
    """A float for strict JSON: inf/NaN become None (callers report exactness apart)."""
    if isinstance(x, float) and (math.isinf(x) or math.isnan(x)):
        return None
    return x


def _equal(ref: np.ndarray, dec: np.ndarray) -> bool:
    """``np.array_equal`` of two light fields, a few views at a time (no whole-size mask)."""
    r, d = _flat(ref), _flat(dec)
    if r.shape != d.shape:
        return False
    k = views_per_chunk(np.prod(r.shape[1:]))
    return all(np.array_equal(r[i:i + k], d[i:i + k]) for i in range(0, r.shape[0], k))


def quality_report(ref: np.ndarray, dec: np.ndarray, *, with_ssim: bool = True) -> dict:
    """Every quality figure of a decode, JSON-able (inf → None, exactness as booleans).

    Args:
        ref, dec: (..., H, W, C) original and decoded views, same dtype.
    """
    acc = QualityAccumulator(with_ssim=with_ssim)
    acc.add(ref, dec)
    return acc.report()


class QualityAccumulator:
    """:func:`quality_report` of a light field given a few views at a time (a decode that is
    never whole in memory: ``lfcodec encode`` measures the file it wrote this way). ``add(ref, dec)`` with (k, H, W, C) or (H, W, C) views of one dtype and size;
    ``report()`` the figures over every view added (each pooled as the whole-array functions
    pool it). ``ssim_threads``: views whose SSIM is computed at once (None: a few; each holds
    about seven float64 copies of a view)."""

    def __init__(self, *, with_ssim: bool = True, ssim_threads: int | None = None):
        self.with_ssim, self.ssim_threads = with_ssim, ssim_threads
        self.sse, self.cnt, self.ssim = [], [], []           # per view: colour squared error, count, SSIM
        self.ycocg, self.n_px = np.zeros(3), 0               # squared errors of the YCoCg-R planes, pixels
        self.exact, self.alpha_exact = True, True
        self.vis, self.alpha = [], []                        # (sse, cnt) over visible pixels, of alpha
        self.any_visible = False
        self.shape = self.peak = None

    def add(self, ref: np.ndarray, dec: np.ndarray) -> None:
        ref, dec = _pair(ref, dec)
        r, d = _flat(ref), _flat(dec).reshape(_flat(ref).shape)
        if self.shape is None:
            self.shape, self.peak = (r.shape[1:], r.dtype), peak_of(r.dtype)
        elif (r.shape[1:], r.dtype) != self.shape:
            raise ParameterError(f"metrics compare views of one shape and dtype: got {r.shape[1:]} {r.dtype} after "
                                 f"{self.shape[0]} {self.shape[1]}")
        k = views_per_chunk(np.prod(r.shape[1:]))
        for i in range(0, r.shape[0], k):
            self._add(r[i:i + k], d[i:i + k])

    def _add(self, r: np.ndarray, d: np.ndarray) -> None:
        c = r.shape[-1]
        cs = colour_channels(c)
        sse, cnt = _sq_err_per_view(r[..., cs], d[..., cs])
        self.sse.append(sse)
        self.cnt.append(cnt)
        self.exact = self.exact and _equal(r[..., cs], d[..., cs])
        if c >= 3:
            e = (to_planes(r[..., :3]) - to_planes(d[..., :3])).astype(np.float64)
            e *= e
            self.ycocg += e.reshape(-1, 3).sum(0)
            self.n_px += r[..., 0].size
        if c in (2, 4):
            mask = r[..., -1] > 0
            self.any_visible = self.any_visible or bool(mask.any())
            self.vis.append(_sq_err_per_view(r[..., cs], d[..., cs], mask))
            self.alpha.append(_sq_err_per_view(r[..., -1:], d[..., -1:]))
            self.alpha_exact = self.alpha_exact and _equal(r[..., -1:], d[..., -1:])
        if self.with_ssim:
            self.ssim += _ssim_views(r, d, self.peak, self.ssim_threads)

    def report(self) -> dict:
        if self.shape is None:
            raise ParameterError("no views were measured")
        peak = self.peak
        sse, cnt = np.concatenate(self.sse), np.concatenate(self.cnt)
        per_view = np.array([_psnr_from_mse(a / n, peak) for a, n in zip(sse, cnt)])
        rgb = _psnr_from_mse(float(sse.sum() / cnt.sum()), peak)
        # (grey: the Y plane is the grey channel)
        ycocg = _ycocg_psnr(self.ycocg, self.n_px, peak) if self.shape[0][-1] >= 3 else rgb
        out = {
            "psnr_rgb": finite(rgb),
            "psnr_ycocg": finite(ycocg),
            "psnr_view_min": finite(float(per_view.min())),
            "psnr_view_mean": finite(float(np.mean(per_view[np.isfinite(per_view)]))) if np.isfinite(per_view).any()
            else None,
            "views_exact": int(np.isinf(per_view).sum()),
            "exact": self.exact,
        }
        if self.shape[0][-1] in (2, 4):
            vs, vc = (np.concatenate(x) for x in zip(*self.vis))
            a_s, a_c = (np.concatenate(x) for x in zip(*self.alpha))
            out["psnr_visible"] = finite(_psnr_from_mse(float(vs.sum() / vc.sum()), peak)) if self.any_visible else None
            out["alpha_exact"] = self.alpha_exact
            out["psnr_alpha"] = finite(_psnr_from_mse(float(a_s.sum() / a_c.sum()), peak))
        if self.with_ssim:
            out["ssim"] = float(np.mean(self.ssim))
        return out
