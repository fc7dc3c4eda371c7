"""RLFC end to end on synthetic and hard cases: exactness, decoder agreement, progressive."""
import numpy as np
import pytest

from formats.errors import LfcError, ParameterError, UnsupportedError
from formats.metrics import psnr_rgb
from rlfc import RlfcParams
from formats.pixels import from_planes, to_planes
from tests.rlfc.helpers import check_agreement, make_lf, roundtrip, smooth_lf


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_ycocg_r_is_lossless(dtype, rng):
    x = rng.integers(0, np.iinfo(dtype).max, (1000, 3), endpoint=True).astype(dtype)
    x[:4] = [[0, 0, 0], [np.iinfo(dtype).max] * 3, [np.iinfo(dtype).max, 0, 0], [0, np.iinfo(dtype).max, 0]]
    p = to_planes(x)
    assert (from_planes(p, dtype) == x).all()
    peak = int(np.iinfo(dtype).max)
    assert p[:, 0].min() >= 0 and p[:, 0].max() <= peak              # Y keeps the depth
    assert p[:, 1:].min() >= -peak and p[:, 1:].max() <= peak         # Co/Cg need one extra bit


@pytest.mark.parametrize("shape", [(300, 256, 3), (70000, 3), (4, 128, 128, 4), (2, 10, 10, 3)])
@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_from_planes_split_path_is_the_same_integers(shape, dtype, rng):
    """Large inputs go through OpenCV-split planes (formats.pixels.SPLIT_MIN); out-of-range planes
    (a residual past the clip) clip the same as the small-input path."""
    from formats.pixels import inverse_int

    peak = int(np.iinfo(dtype).max)
    p = rng.integers(-2 * peak, 2 * peak, shape).astype(np.int32)
    ref = np.clip(inverse_int(p.copy()), 0, peak).astype(dtype)
    got = from_planes(p, dtype)
    assert got.dtype == dtype and got.shape == ref.shape and np.array_equal(got, ref)
    x = rng.integers(0, peak, shape, endpoint=True).astype(dtype)
    assert np.array_equal(from_planes(to_planes(x), dtype), x)
    if len(shape) >= 3:                               # views cropped from padded planes (row strides)
        crop = p[..., 1:shape[-2] - 1, :] if len(shape) == 3 else p[:, 1:, 2:]
        assert np.array_equal(from_planes(crop, dtype), np.clip(inverse_int(crop.copy()), 0, peak).astype(dtype))
    if dtype is np.uint8:                             # another output type: numpy's clip, not OpenCV's saturation
        assert np.array_equal(from_planes(p, np.int32), np.clip(inverse_int(p.copy()), 0, 255))


def test_from_planes_scratch_is_per_thread_and_never_returned(rng):
    """The split path's planes are kept per thread (formats.pixels._scratch_planes): calls of
    growing and shrinking sizes on two threads at once give inverse_int's integers, and no
    result shares memory with a thread's planes."""
    import threading

    from formats import pixels
    from formats.pixels import inverse_int

    inputs = [rng.integers(-300, 600, s).astype(np.int32) for s in
              [(300, 256, 3), (40, 3000, 3), (2, 128, 128, 4), (600, 700, 3), (70000, 3)]]
    refs = [np.clip(inverse_int(p.copy()), 0, 255).astype(np.uint8) for p in inputs]
    bad, held = [], []

    def work(order):
        for i in order * 3:
            got = pixels.from_planes(inputs[i])
            planes = pixels._SCRATCH.planes
            if not np.array_equal(got, refs[i]) or any(np.shares_memory(got, q) for q in planes):
                bad.append(i)
        held.append(pixels._SCRATCH.planes)

    threads = [threading.Thread(target=work, args=(o,)) for o in ([0, 1, 2, 3, 4], [4, 3, 2, 1, 0])]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not bad and len(held) == 2
    assert not any(np.shares_memory(a, b) for a in held[0] for b in held[1])     # each thread its own


@pytest.mark.parametrize("shape", [(300, 256, 3), (4, 128, 128, 4), (2, 10, 10, 3), (512, 512, 3)])
@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_to_planes_split_path_is_the_same_integers(shape, dtype, rng):
    """Large contiguous inputs go through OpenCV-split planes; a strided view takes the general
    path; both give forward_int's integers."""
    from formats.pixels import forward_int

    peak = int(np.iinfo(dtype).max)
    x = rng.integers(0, peak, shape, endpoint=True).astype(dtype)
    x.reshape(-1, shape[-1])[:3] = [[peak] * shape[-1], [0] * shape[-1], [peak, 0, peak] + [0] * (shape[-1] - 3)]
    ref = forward_int(x.astype(np.int32))
    got = to_planes(x)
    assert got.dtype == np.int32 and got.shape == x.shape and np.array_equal(got, ref)
    crop = x[..., 1:, :]
    assert np.array_equal(to_planes(crop), forward_int(crop.astype(np.int32)))


def test_luma_is_to_planes_y_on_every_8_bit_colour():
    """formats.pixels.luma_of (the map estimation's luma: Y's lifting steps alone, in int16) is
    to_planes' Y on all 2^24 8-bit RGB colours, as an RGB and an RGBA image."""
    from formats.pixels import luma_of

    v = np.arange(256, dtype=np.uint8)
    x = np.stack(np.meshgrid(v, v, v, indexing="ij"), -1).reshape(4096, 4096, 3)
    y = luma_of(x)
    assert y.dtype == np.uint8 and y.shape == (4096, 4096) and np.array_equal(y, to_planes(x)[..., 0])
    xa = np.concatenate([x[:64], np.full((64, 4096, 1), 7, np.uint8)], -1)
    assert np.array_equal(luma_of(xa), to_planes(xa)[..., 0])


@pytest.mark.parametrize("c", [1, 2, 3, 4])
@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_luma_is_to_planes_y(c, dtype, rng):
    """luma_of on grey, grey + alpha, RGB and RGBA at both depths (extremes included), on a
    contiguous view and on a strided crop (the general path): to_planes' Y in the input's dtype."""
    from formats.pixels import luma_of

    peak = int(np.iinfo(dtype).max)
    x = rng.integers(0, peak, (37, 41, c), endpoint=True).astype(dtype)
    x[0, :3] = [[peak] * c, [0] * c, ([peak, 0, peak, 0] if c >= 3 else [peak, 0])[:c]]
    for img in (x, x[3:, 5:]):
        y = luma_of(img)
        assert y.dtype == dtype and y.shape == img.shape[:-1]
        assert np.array_equal(y, to_planes(img)[..., 0].astype(dtype))


@pytest.mark.parametrize("kw", [dict(), dict(dtype=np.uint16), dict(c=1), dict(c=4), dict(c=2),
                                dict(h=13, w=19), dict(rows=1, cols=5), dict(rows=5, cols=1)])
def test_lossless_exact_and_decoders_agree(kw):
    lf = smooth_lf(**kw)
    d, n, loop = roundtrip(lf, RlfcParams(block_size=4, quant=1, tree_height=2))
    assert (d.decode_all() == lf.views).all()
    check_agreement(d, lf.views.shape)


@pytest.mark.parametrize("kw", [dict(), dict(dtype=np.uint16), dict(c=1), dict(c=4), dict(h=13, w=19)])
def test_lossy_decoders_agree_and_match_encoder(kw):
    lf = smooth_lf(**kw)
    d, n, loop = roundtrip(lf, RlfcParams(block_size=4, quant=6, threshold=3, energy=9, tree_height=2))
    full = d.decode_all()
    enc_view = from_planes(loop.dec0[:, :lf.height, :lf.width], lf.views.dtype)
    assert (full.reshape(enc_view.shape) == enc_view).all()   # closed loop: encoder == decoder
    check_agreement(d, lf.views.shape)
    assert psnr_rgb(lf.views, full) > 30


def test_alpha_is_lossless_in_lossy_mode(rng):
    lf = smooth_lf(c=4)
    # small alpha wiggles: far below the block-energy threshold, yet they must survive
    lf.views[..., 3] = (200 + rng.integers(0, 3, lf.views.shape[:-1])).astype(np.uint8)
    d, _, _ = roundtrip(lf, RlfcParams(block_size=4, quant=12, threshold=6, energy=36))
    assert (d.decode_all()[..., 3] == lf.views[..., 3]).all()


def test_progressive_levels_improve_monotonically():
    lf = smooth_lf(rows=5, cols=5)
    d, _, _ = roundtrip(lf, RlfcParams(block_size=4, quant=2, tree_height=3))
    ps = [psnr_rgb(lf.views, d.decode_all(L)) for L in range(d.levels + 1)]
    assert all(a >= b for a, b in zip(ps, ps[1:])), ps


def test_constant_light_field_costs_little():
    v = np.full((4, 4, 32, 32, 3), 77, dtype=np.uint8)
    d, n, _ = roundtrip(make_lf(v), RlfcParams(quant=4))
    assert (d.decode_all() == v).all()
    assert n < 4000                      # header + tiny key views; no residual blocks at all
    assert d.file.meta["config"]["n_blocks"] == 0


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_saturated_colours(dtype):
    peak = np.iinfo(dtype).max
    v = np.zeros((3, 3, 16, 16, 3), dtype=dtype)
    v[..., 0] = peak
    v[::2, :, :8, :, 1] = peak
    v[:, 1::2, :, 8:, 2] = peak
    d, _, _ = roundtrip(make_lf(v), RlfcParams(block_size=4, quant=1))
    assert (d.decode_all() == v).all()
    d, _, _ = roundtrip(make_lf(v), RlfcParams(block_size=4, quant=8, threshold=4, energy=16))
    out = d.decode_all()
    assert out.min() >= 0 and out.max() <= peak and psnr_rgb(v, out) > 20


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_uniform_noise_stays_near_raw_size(dtype, rng):
    v = rng.integers(0, np.iinfo(dtype).max, (4, 4, 32, 32, 3), endpoint=True).astype(dtype)
    raw = v.nbytes
    for q in (1, 4):
        d, n, _ = roundtrip(make_lf(v), RlfcParams(quant=q, threshold=0 if q == 1 else 2))
        assert n <= raw * 1.15 + 4096, (q, n, raw)
    d, n, _ = roundtrip(make_lf(v), RlfcParams(quant=1))
    assert (d.decode_all() == v).all()


@pytest.mark.parametrize("shape", [(1, 1, 3, 5, 3), (2, 2, 3, 5, 3), (1, 1, 40, 40, 3), (2, 3, 1, 1, 1)])
def test_tiny_views_and_single_view(shape, rng):
    v = rng.integers(0, 256, shape).astype(np.uint8)
    d, _, _ = roundtrip(make_lf(v), RlfcParams(quant=1))
    assert (d.decode_all() == v).all()
    assert d.decode_block(0, 0, 0, 0).shape == (min(8, shape[2]), min(8, shape[3]), shape[4])


def test_irregular_cameras_cluster_by_distance(rng):
    lf = smooth_lf(rows=1, cols=9)
    lf.layout = "posed"
    lf.positions = rng.random((1, 9, 3))
    d, _, _ = roundtrip(lf, RlfcParams(block_size=4, quant=1, tree_height=2))
    assert (d.decode_all() == lf.views).all()
    assert d.core.tree.sizes[1] == 3


def test_float_views_are_unsupported():
    lf = make_lf(np.zeros((1, 2, 4, 4, 3), np.float32))
    with pytest.raises(UnsupportedError, match="16-bit"):
        roundtrip(lf)


@pytest.mark.parametrize("profile", ["auto", "tx", "dcp", "bise"])
def test_float_views_are_unsupported_by_every_profile(profile):
    """Float views (an HDR TIFF folder reads as float32) used to reach the tx encoder and stop
    there with numpy's ValueError: the codec refuses them, typed, before any work."""
    from formats.codec_api import EncodeOptions
    from rlfc import encode

    lf = make_lf(np.zeros((2, 2, 8, 8, 3), np.float32))
    with pytest.raises(UnsupportedError, match="8- and 16-bit integer views; these are float32"):
        encode(lf, EncodeOptions(profile=profile, target_psnr=40))


@pytest.mark.parametrize("kw", [dict(block_size=3), dict(quant=0.5), dict(tree_height=-1), dict(threshold=-1),
                                dict(top_codec="png"), dict(profile="nope")])
def test_bad_params(kw):
    with pytest.raises(ParameterError):
        RlfcParams(**kw)


def test_bad_requests_are_typed():
    d, _, _ = roundtrip(smooth_lf(), RlfcParams(block_size=4))
    for bad in (lambda: d.decode_block(9, 0, 0, 0), lambda: d.decode_block(0, 0, 99, 0),
                lambda: d.decode_view(0, 0, level=7), lambda: d.decode_blocks([0], [0], [99])):
        with pytest.raises(LfcError):
            bad()



def test_too_many_block_requests_are_refused_before_allocating():
    """A call whose output would pass Limits.max_scene_pixels (2^32 pixels: 12 GiB of RGB) is a
    ParameterError naming the most blocks a call may ask, before any request-sized array (10^8
    requests of 8x8 blocks were numpy's MemoryError); a caller's own limits set the cap."""
    from formats.container import build_container
    from formats.lfcfile import encode_meta, open_lfc
    from formats.limits import Limits
    from rlfc import RlfcDecoder, encode_with_params

    lf = smooth_lf()
    cfg, sections, _ = encode_with_params(lf, RlfcParams(block_size=4))
    blob = b"".join(bytes(p) for p in build_container(encode_meta("rlfc", 1, cfg, lf.geometry()), sections))
    d = RlfcDecoder(open_lfc(blob))
    many = np.broadcast_to(np.int8(0), (2 ** 28 + 1,))            # no memory of its own
    with pytest.raises(ParameterError, match="request at most 268435456 blocks per call"):
        d.decode_blocks(many, many, many)
    small = RlfcDecoder(open_lfc(blob, limits=Limits(max_scene_pixels=100)))
    with pytest.raises(ParameterError, match="at most 6 blocks"):
        small.decode_blocks([0] * 7, [0] * 7, [0] * 7)
    assert small.decode_blocks([0] * 6, [0] * 6, [0] * 6).shape == (6, 4, 4, 3)
    # the limits a file was opened with hold at open too (header and profile), not only per call
    from formats.errors import FormatError
    with pytest.raises(FormatError, match="limit"):
        RlfcDecoder(open_lfc(blob, limits=Limits(max_view_pixels=lf.height * lf.width - 1)))
    with pytest.raises(FormatError, match="limit"):
        RlfcDecoder(open_lfc(blob), limits=Limits(max_view_pixels=lf.height * lf.width - 1))


def test_lossy_top_level_feeds_the_closed_loop():
    lf = smooth_lf(rows=4, cols=4)
    d, n_lossy, loop = roundtrip(lf, RlfcParams(block_size=4, quant=1, tree_height=2, top_psnr=30))
    # lossy key views, yet the residuals are computed against their decoded pixels: exact views
    assert (d.decode_all() == lf.views).all()
    assert psnr_rgb(lf.views, d.decode_all(d.levels)) < 60          # the top level itself is lossy
    check_agreement(d, lf.views.shape)
    assert {t["codec"] for t in d.file.meta["config"]["top"]} == {"j2k"}


@pytest.mark.parametrize("kw,params", [
    (dict(), RlfcParams(block_size=4, quant=6, threshold=3, energy=9, tree_height=2)),
    (dict(dtype=np.uint16, c=4), RlfcParams(block_size=4, quant=3, tree_height=2)),
    (dict(c=1, h=13, w=19), RlfcParams(block_size=8, quant=1)),
])
def test_torch_batched_decoder_is_bit_exact(kw, params, rng):
    from rlfc.torch_decode import TorchBlockDecoder

    lf = smooth_lf(**kw)
    d, _, _ = roundtrip(lf, params)
    n = 500
    views, by, bx = rng.integers(0, d.rows * d.cols, n), rng.integers(0, d.nby, n), rng.integers(0, d.nbx, n)
    td = TorchBlockDecoder(d, "cpu")
    for level in range(d.levels + 1):
        assert (td.decode_blocks(views, by, bx, level) == d.decode_blocks(views, by, bx, level)).all()


def test_torch_decoder_handles_raw_and_wide_blocks(rng):
    from rlfc.torch_decode import TorchBlockDecoder

    v = rng.integers(0, 65536, (3, 3, 16, 16, 3)).astype(np.uint16)      # noise: raw and plain-bit modes
    d, _, _ = roundtrip(make_lf(v), RlfcParams(block_size=4, quant=2))
    assert d.file.meta["config"]["n_raw_blocks"] > 0
    views = np.arange(9).repeat(16)
    by, bx = np.tile(np.repeat(np.arange(4), 4), 9), np.tile(np.arange(4), 36)
    assert (TorchBlockDecoder(d, "cpu").decode_blocks(views, by, bx) == d.decode_blocks(views, by, bx)).all()


def test_byte_range_source_fetches_only_what_a_block_needs():
    from formats.container import ByteRangeSource, build_container
    from formats.lfcfile import encode_meta, open_lfc
    from rlfc import RlfcDecoder, encode_with_params

    lf = smooth_lf(rows=5, cols=5, h=64, w=64)
    cfg, sections, _ = encode_with_params(lf, RlfcParams(block_size=4, quant=2))
    blob = b"".join(bytes(p) for p in build_container(encode_meta("rlfc", 1, cfg, lf.geometry()), sections, 1024))
    local = RlfcDecoder(open_lfc(blob))
    src = ByteRangeSource(lambda a, b: blob[a:b], len(blob))
    remote = RlfcDecoder(open_lfc(src))
    opened = src.bytes_fetched
    blocks_len = remote.file.container.info("rlfc.blocks").length
    assert opened < len(blob) - blocks_len + 1      # opening never reads the blocks section
    assert (remote.decode_block(2, 3, 5, 7) == local.decode_block(2, 3, 5, 7)).all()
    assert src.bytes_fetched - opened <= 2 * 1024   # one run, verified chunk by chunk
    v, by, bx = np.arange(25), np.arange(25) % 16, (np.arange(25) * 7) % 16
    assert (remote.decode_blocks(v, by, bx) == local.decode_blocks(v, by, bx)).all()
    assert (remote.decode_view(4, 4, level=1) == local.decode_view(4, 4, level=1)).all()
