"""Encode options of the wrong type, through the Python API: a ParameterError naming the option
before any work (a string target or step used to meet a range test deep in an encode as a
TypeError or ValueError)."""
import numpy as np
import pytest

from formats import EncodeOptions, get_codec
from formats.errors import ParameterError
from tests.rlfc.helpers import smooth_lf


@pytest.fixture(scope="module")
def lf():
    return smooth_lf(rows=2, cols=2, h=16, w=16)


@pytest.mark.parametrize("kw, why", [({"target_psnr": "40"}, "target_psnr must be a number"),
                                     ({"target_bpp": [1]}, "target_bpp must be a number"),
                                     ({"min_view_psnr": "x"}, "min_view_psnr"),
                                     ({"lossless": 1}, "lossless must be true or false"),
                                     ({"params": [("step", 4)]}, "params must be a dict")])
def test_encode_options_of_the_wrong_type(kw, why):
    with pytest.raises(ParameterError, match=why):
        EncodeOptions(**kw)
    assert EncodeOptions(target_psnr=np.float32(40)).target_psnr == 40     # numpy numbers are numbers


@pytest.mark.parametrize("profile, params, why", [
    ("tx", {"step": "x"}, "step must be a number or None"), ("tx", {"lam": None}, "lam must be a number"),
    ("tx", {"block_size": "16"}, "block_size must be a number"), ("tx", {"quant": "8"}, "--quant must be a number"),
    ("dcp", {"max_disparity": "x"}, "max_disparity must be a number"), ("dcp", {"top_psnr": "x"}, "top_psnr"),
    ("bise", {"threshold": [1]}, "threshold must be a number"), ("bise", {"quant": "x"}, "--quant must be a number")])
def test_codec_params_of_the_wrong_type(lf, profile, params, why):
    with pytest.raises(ParameterError, match=why):
        get_codec("rlfc").encode(lf, EncodeOptions(profile=profile, params=params))


def test_lfn_params_of_the_wrong_type(lf):
    for params, why in (({"resolution": "x"}, "--resolution must be a number"), ({"device": 3}, "--device must be a string")):
        with pytest.raises(ParameterError, match=why):
            get_codec("lfn").encode(lf, EncodeOptions(params=params))
