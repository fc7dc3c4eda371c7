"""Metrics measure a light field a few views at a time; the chunking changes no figure."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import formats.metrics as M


@pytest.mark.parametrize("channels,dtype", [(1, np.uint8), (2, np.uint16), (3, np.uint8), (4, np.uint16)])
def test_quality_report_in_chunks_equals_one_chunk(channels, dtype, monkeypatch):
    rng = np.random.default_rng(channels)
    peak = np.iinfo(dtype).max
    ref = rng.integers(0, peak, (3, 4, 9, 7, channels), endpoint=True).astype(dtype)
    dec = ref.copy()
    noisy = rng.random(ref.shape) < 0.3
    dec[noisy] = rng.integers(0, peak, int(noisy.sum()), endpoint=True).astype(dtype)
    dec[1, 2] = ref[1, 2]                                    # one exact view
    whole = M.quality_report(ref, dec, with_ssim=False)
    monkeypatch.setattr(M, "CHUNK_ELEMENTS", 5)              # one view at a time
    small = M.quality_report(ref, dec, with_ssim=False)
    assert small == whole and whole["views_exact"] == 1 and whole["exact"] is False
    assert M.quality_report(ref, ref.copy(), with_ssim=False)["exact"] is True
    if channels in (2, 4):
        assert whole["alpha_exact"] is False
        d2 = dec.copy()
        d2[..., -1] = ref[..., -1]
        assert M.quality_report(ref, d2, with_ssim=False)["alpha_exact"] is True
    # the pooled PSNR is the one every view's squared errors give
    sse, cnt = M.colour_sq_error(ref, dec)
    assert whole["psnr_rgb"] == pytest.approx(M.psnr_from_sq_error(np.array([sse]), np.array([cnt]), peak))


@pytest.mark.parametrize("channels,dtype", [(1, np.uint16), (3, np.uint8), (4, np.uint16)])
def test_one_view_measured_in_bands_of_rows(channels, dtype, monkeypatch):
    """One view larger than BAND_ELEMENTS (what an encoder measures each view it codes with) is
    measured in bands of rows: the same sums, exactly, as the view at once."""
    rng = np.random.default_rng(20 + channels)
    peak = np.iinfo(dtype).max
    ref = rng.integers(0, peak, (37, 23, channels), endpoint=True).astype(dtype)
    dec = rng.integers(0, peak, ref.shape, endpoint=True).astype(dtype)
    whole = M.colour_sq_error(ref, dec)
    e = ref[..., M.colour_channels(channels)].astype(np.float64) - dec[..., M.colour_channels(channels)]
    assert whole == (float((e * e).sum()), float(e.size))
    monkeypatch.setattr(M, "BAND_ELEMENTS", 2 * 23 * channels + 1)     # bands of 2 rows, the last of 1
    assert M.colour_sq_error(ref, dec) == whole
    monkeypatch.setattr(M, "BAND_ELEMENTS", 1)                         # a row at a time
    assert M.colour_sq_error(ref, dec) == whole
    assert M.colour_sq_error(ref[None, None], dec[None, None]) == whole


@pytest.mark.parametrize("channels,dtype", [(1, np.uint8), (2, np.uint16), (3, np.uint16), (4, np.uint8)])
def test_quality_of_views_added_one_at_a_time(channels, dtype):
    """QualityAccumulator (what ``lfcodec encode`` measures the written file with, one row of
    views at a time) gives every figure of the whole-array functions: pooled, YCoCg, per-view,
    visible, alpha PSNR, SSIM and exactness; a view of another size is refused."""
    from formats.errors import ParameterError

    rng = np.random.default_rng(10 + channels)
    peak = np.iinfo(dtype).max
    ref = rng.integers(0, peak, (2, 3, 12, 10, channels), endpoint=True).astype(dtype)
    dec = np.clip(ref.astype(np.int64) + rng.integers(-40, 41, ref.shape), 0, peak).astype(dtype)
    dec[0, 1] = ref[0, 1]
    if channels in (2, 4):
        ref[1, :, :, :, -1] = 0                               # a row of views with nothing visible
    acc = M.QualityAccumulator()
    for r in range(2):
        acc.add(ref[r, 0], dec[r, 0])                        # one view
        acc.add(ref[r, 1:], dec[r, 1:])                      # two views
    got = acc.report()
    want = {"psnr_rgb": M.psnr_rgb(ref, dec), "psnr_ycocg": M.psnr_ycocg(ref, dec),
            "psnr_view_min": float(M.psnr_views(ref, dec).min()), "ssim": M.ssim(ref, dec)}
    if channels in (2, 4):
        want.update(psnr_visible=M.psnr_visible(ref, dec), psnr_alpha=M.psnr_alpha(ref, dec))
    for k, v in want.items():
        assert got[k] == pytest.approx(v, rel=1e-12), k
    assert got["views_exact"] == 1 and got["exact"] is False
    with pytest.raises(ParameterError, match="one shape"):
        acc.add(ref[0, 0, :6], dec[0, 0, :6])
    with pytest.raises(ParameterError, match="no views"):
        M.QualityAccumulator().report()


def test_metrics_refuse_views_that_do_not_compare():
    """Views of another size, no pixels, or another depth: a ParameterError each (before: numpy's
    reshape error, nan with a warning, or a figure on the reference's peak)."""
    from formats.errors import ParameterError

    a = np.zeros((2, 4, 4, 3), np.uint8)
    for f in (M.mse, M.psnr_rgb, M.psnr_views, M.psnr_ycocg, M.ssim, M.quality_report, M.colour_sq_error):
        with pytest.raises(ParameterError, match="one shape"):
            f(a, a[:, :2])
        with pytest.raises(ParameterError, match="need pixels"):
            f(a[:0], a[:0])
        with pytest.raises(ParameterError, match="one depth"):
            f(a, a.astype(np.uint16))
    assert M.psnr_rgb(a, a.reshape(1, 2, 4, 4, 3)) == float("inf")      # a grid against a stack
    assert M.mse(a, a.astype(np.int32)) == 0.0                            # decoded integer planes


@pytest.mark.parametrize("channels,dtype,shape", [(3, np.uint8, (40, 33)), (1, np.uint16, (7, 12)), (4, np.uint8, (9, 7)),
                                                  (2, np.uint16, (16, 16)), (3, np.float32, (21, 18))])
def test_ssim_is_scikit_images(channels, dtype, shape):
    """SSIM (OpenCV box filters, in place) equals scikit-image's structural_similarity averaged
    over views, on the colour channels: 8/16-bit, grey, alpha left out, float, the 7-px minimum;
    a view under 7 px a side counts 1 when exact, else 0."""
    from skimage.metrics import structural_similarity

    rng = np.random.default_rng(channels + len(shape) + shape[0])
    peak = 1.0 if dtype == np.float32 else float(np.iinfo(dtype).max)
    smooth = np.cumsum(rng.random((3, *shape, channels)), axis=1)      # structure as well as noise
    ref = (smooth / smooth.max() * peak).astype(dtype)
    noise = rng.normal(0, 0.03 * peak, ref.shape)
    dec = np.clip(ref + noise, 0, peak).astype(dtype)
    cs = slice(0, 3) if channels >= 3 else slice(0, 1)
    want = np.mean([structural_similarity(ref[i][..., cs], dec[i][..., cs], channel_axis=-1, data_range=peak)
                    for i in range(3)])
    assert M.ssim(ref, dec) == pytest.approx(want, abs=1e-6 if dtype == np.float32 else 1e-12)
    assert M.ssim(ref, ref.copy()) == pytest.approx(1.0, abs=1e-12)
    tiny = ref[:, :6, :5]
    assert M.ssim(tiny, tiny.copy()) == 1.0 and M.ssim(tiny, dec[:, :6, :5]) == 0.0
    if dtype == np.float32:                  # a float32 image against a float64 one: float64, as scikit-image
        d64 = dec[0].astype(np.float64)
        want64 = structural_similarity(ref[0][..., cs], d64[..., cs], channel_axis=-1, data_range=peak)
        assert M.ssim_image(ref[0][..., cs], d64[..., cs], peak) == pytest.approx(want64, abs=1e-12)


@settings(max_examples=60, deadline=None, derandomize=True)
@given(st.integers(1, 3), st.integers(1, 40), st.integers(1, 40), st.integers(1, 4), st.sampled_from([np.uint8, np.uint16]),
       st.integers(0, 2 ** 32 - 1), st.sampled_from(["random", "extreme", "equal"]))
def test_squared_errors_are_the_exact_integer_sums(n, h, w, c, dtype, seed, kind):
    """The per-view squared errors (OpenCV's integer L2² norm for contiguous 8-bit views, numpy
    in float64 otherwise) are the exact sums of integer squares, on every path: 8-bit and
    16-bit, grey to RGBA (the colour slice of RGBA or grey+alpha takes numpy's path), several
    views at once or a band at a time."""
    rng = np.random.default_rng(seed)
    peak = int(np.iinfo(dtype).max)
    ref = rng.integers(0, peak, (n, h, w, c), endpoint=True).astype(dtype)
    if kind == "random":
        dec = rng.integers(0, peak, ref.shape, endpoint=True).astype(dtype)
    elif kind == "extreme":
        ref[:] = 0
        dec = np.full(ref.shape, peak, dtype)
    else:
        dec = ref.copy()
    cs = M.colour_channels(c)
    want = float(((ref[..., cs].astype(np.int64) - dec[..., cs].astype(np.int64)) ** 2).sum())
    assert M.colour_sq_error(ref, dec) == (want, float(n * h * w * (cs.stop - cs.start)))
    every = ((ref.astype(np.int64) - dec.astype(np.int64)) ** 2).reshape(n, -1).sum(1)
    sse, cnt = M._sq_err_per_view(ref, dec)
    assert sse.tolist() == every.astype(float).tolist() and cnt.tolist() == [float(h * w * c)] * n
    assert M.mse(ref, dec) == float(every.sum()) / (n * h * w * c)


def test_eight_bit_norm_is_exact_where_a_float_sum_would_round():
    """A 2048×2048 RGB view at the largest error everywhere: 3.2·10^11, beyond float32's integers
    (a float accumulation would round); the fast path gives it exactly."""
    ref = np.zeros((2048, 2048, 3), np.uint8)
    dec = np.full_like(ref, 255)
    assert M._exact_norm(ref[None], dec[None])
    assert M.colour_sq_error(ref, dec) == (2048.0 * 2048 * 3 * 255 ** 2, 2048.0 * 2048 * 3)
    dec[7, 9, 1] = 254
    assert M.colour_sq_error(ref, dec)[0] == 2048.0 * 2048 * 3 * 255 ** 2 - 255 ** 2 + 254 ** 2
