"""The decoders' Python API: arguments that are not what a call takes are ParameterErrors (an
LfcError), never an untyped exception, and never a silently different view or block (a float
index used to pick view or block 0)."""
import numpy as np
import pytest

from formats.errors import ParameterError
from formats.lfcfile import open_lfc
from formats.registry import open_decoder
from tests.conftest import ROOT

GOLDEN = ROOT / "tests" / "data" / "golden"


@pytest.fixture(params=["rlfc_tx_lossy_rgb8.lfc", "rlfc_txsplit_lossy_rgb8.lfc", "lfn3_tiny_rgba8.lfc"])
def dec(request):
    with open_lfc(GOLDEN / request.param) as f:
        yield open_decoder(f)


@pytest.mark.parametrize("call", [
    lambda d: d.decode_view(0.0, 0), lambda d: d.decode_view(0, 0.5), lambda d: d.decode_view(True, 0),
    lambda d: d.decode_view(0, 0, level=float("nan")), lambda d: d.decode_view(0, 0, level=float("inf")),
    lambda d: d.decode_view(0, 0, level="0"), lambda d: d.decode_views(np.array([0.5])),
    lambda d: d.decode_views([True]), lambda d: d.decode_views("0"), lambda d: d.decode_views([10 ** 9]),
])
def test_bad_arguments_are_parameter_errors(dec, call):
    with pytest.raises(ParameterError):
        call(dec)


def test_integer_arguments_of_any_integer_type(dec):
    want = dec.decode_view(0, 1)
    assert np.array_equal(dec.decode_view(np.int64(0), np.int32(1)), want)
    assert np.array_equal(dec.decode_views(np.array([1], np.uint8))[0], want)
    assert dec.decode_views([]).shape == (0, dec.height, dec.width, dec.channels)


def test_rlfc_blocks_and_renderer_arguments():
    with open_lfc(GOLDEN / "rlfc_tx_lossy_rgb8.lfc") as f:
        d = open_decoder(f)
        want = d.decode_block(0, 1, 0, 1)
        assert np.array_equal(d.decode_block(np.int64(0), 1, np.int16(0), 1), want)
        for bad in ((0, 1, 0.5, 1), (0, 1, 0, True), (0, 1.0, 0, 1)):
            with pytest.raises(ParameterError):
                d.decode_block(*bad)
        for kw in (dict(cache_mib=float("nan")), dict(cache_mib=-1), dict(cache_mib="1"), dict(margin=-1.0),
                   dict(margin=float("inf"))):
            with pytest.raises(ParameterError):
                d.renderer(**kw)


def test_lfn_camera_and_size_arguments():
    # a NaN scale or size was a ValueError from int(); a scale of 100 rendered a view 100x the
    # captured size (now bounded as foveation_map's: (0, 64] and Limits.max_view_pixels); a NaN
    # gaze or inner > outer made a foveation map without a word
    with open_lfc(GOLDEN / "lfn3_tiny_rgba8.lfc") as f:
        d = open_decoder(f)
        pose = d.pose(0, 0)
        for call in (lambda: d.render_pose(pose, scale=float("nan")), lambda: d.render_pose(pose, scale=0),
                     lambda: d.render_pose(pose, scale=100), lambda: d.render_pose(pose, neurons=float("nan")),
                     lambda: d.render_pose(pose, neurons="8"), lambda: d.render(0, 0, scale=1e9),
                     lambda: d.render(0, 0, neurons=float("nan")), lambda: d.foveation_map((float("nan"), 1.0)),
                     lambda: d.foveation_map((1.0, 1.0), inner=0.9, outer=0.1)):
            with pytest.raises(ParameterError):
                call()
        assert d.render(0, 0, neurons=d.neuron_range[1], scale=0.5).shape[2] == 4
        assert d.foveation_map((10.0, 10.0)).shape == (d.height, d.width)


@pytest.mark.parametrize("device", ["bogus", 3.5] + ([] if __import__("torch").cuda.is_available() else ["cuda"]))
def test_devices_that_cannot_be_used_are_parameter_errors(device):
    # the torch block decoder and the LFN renderer raised torch's RuntimeError / AssertionError
    from rlfc.torch_decode import TorchBlockDecoder

    with open_lfc(GOLDEN / "rlfc_tx_lossy_rgb8.lfc") as f:
        d = open_decoder(f)
        with pytest.raises(ParameterError, match="not usable"):
            TorchBlockDecoder(d, device=device)
        with pytest.raises(ParameterError):
            d.renderer(device=device)
    with open_lfc(GOLDEN / "lfn3_tiny_rgba8.lfc") as f, pytest.raises(ParameterError, match="not usable"):
        open_decoder(f, device=device)


@pytest.mark.parametrize("name", ["rlfc_tx_lossy_rgb8.lfc", "rlfc_tx2_lossless_ga16.lfc"])
def test_a_closed_file_reads_nothing_more(name):
    """After close (or the end of a with block), decoding through a decoder made before, or
    making a new one, is a ParameterError saying the file is closed, not pixels read from a
    released map or a new connection; closing twice is allowed."""
    f = open_lfc(GOLDEN / name)
    d = open_decoder(f)
    want = d.decode_block(0, 1, 0, 0)
    f.close()
    f.close()
    for call in (lambda: d.decode_block(0, 1, 0, 0), lambda: d.decode_view(0, 1), lambda: d.decode_blocks([1], [0], [0]),
                 lambda: open_decoder(f)):
        with pytest.raises(ParameterError, match="closed"):
            call()
    with open_lfc(GOLDEN / name) as g:
        assert np.array_equal(open_decoder(g).decode_block(0, 1, 0, 0), want)
