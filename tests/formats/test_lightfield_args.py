"""A LightField built from Python checks what a file's geometry will hold: positions, poses,
intrinsics and layout are finite and of the views' shape (NaN positions used to pass until the
file was written, after the whole encode), and the library's encode takes one rate target."""
import numpy as np
import pytest

from formats.codec_api import EncodeOptions
from formats.errors import ParameterError, SceneError
from formats.lightfield import LightField, grid_positions
from rlfc import encode

V = np.zeros((2, 2, 8, 8, 3), np.uint8)
P = grid_positions(2, 2)


@pytest.mark.parametrize("kw", [dict(views=V.tolist()), dict(positions=np.full((2, 2, 3), np.nan)),
                                dict(positions=np.zeros((3, 3))), dict(positions="abc"),
                                dict(c2w=np.zeros((2, 2, 4, 3))), dict(c2w=np.full((2, 2, 4, 4), np.inf)),
                                dict(focal=(-1.0, 1.0)), dict(focal=(0.0, 0.0)), dict(focal=(np.nan, 1.0)),
                                dict(focal=(1.0,)), dict(principal=(np.inf, 0.0)), dict(layout="weird")])
def test_bad_geometry_is_a_scene_error(kw):
    with pytest.raises(SceneError):
        LightField(**{"views": V, "positions": P, **kw})


def test_good_geometry_of_any_array_shape():
    lf = LightField(views=V, positions=P.reshape(4, 3), c2w=np.tile(np.eye(4), (4, 1, 1)), focal=(10, 12),
                    layout="posed")
    assert lf.positions.shape == (2, 2, 3) and lf.c2w.shape == (2, 2, 4, 4) and lf.principal == (4.0, 4.0)


def test_one_rate_target():
    lf = LightField(views=V, positions=P)
    with pytest.raises(ParameterError, match="one rate target"):
        encode(lf, EncodeOptions(target_psnr=40, target_bpp=1.0))
