"""Light fields from arrays users already have (numpy, memmap, dask), read one view at a time."""
import numpy as np
import pytest

from formats import EncodeOptions, from_array
from formats.errors import SceneError
from formats.lightfield import LightField, grid_positions
from formats.viewstack import ViewStack
from rlfc.codec import RlfcCodec
from tests.rlfc.helpers import smooth_lf


class CountingArray:
    """An array-like that counts what is read (stands for a zarr array on disk)."""

    def __init__(self, a):
        self.a, self.shape, self.dtype, self.reads = a, a.shape, a.dtype, 0

    def __getitem__(self, k):
        self.reads += 1
        return self.a[k]


def test_views_are_read_one_at_a_time_and_match():
    v = np.arange(6 * 5 * 7 * 3, dtype=np.uint16).reshape(6, 5, 7, 3)
    src = CountingArray(v)
    vs = ViewStack(src, grid=(2, 3))
    assert vs.shape == (2, 3, 5, 7, 3) and vs.dtype == np.uint16 and src.reads == 0
    assert (vs[1, 2] == v[5]).all() and src.reads == 1
    assert (np.asarray(vs) == v.reshape(2, 3, 5, 7, 3)).all()


def test_grey_and_five_d_arrays():
    g = np.zeros((4, 5, 6), np.uint8)
    assert ViewStack(g, grid=(2, 2)).shape == (2, 2, 5, 6, 1)
    five = np.zeros((2, 2, 5, 6, 3), np.uint8)
    assert (ViewStack(five)[1, 1] == five[1, 1]).all()


@pytest.mark.parametrize("arr,grid,needle", [
    (np.zeros((6, 5, 7, 3), np.uint8), (2, 2), "does not hold"),
    (np.zeros((5, 7), np.uint8), None, "shape"),
    ([1, 2, 3], None, "shape"),
])
def test_bad_arrays_are_scene_errors(arr, grid, needle):
    with pytest.raises(SceneError, match=needle):
        ViewStack(arr, grid)


def test_dask_and_memmap_sources_encode_to_the_same_file(tmp_path):
    da = pytest.importorskip("dask.array")
    lf = smooth_lf(rows=3, cols=3, h=24, w=32)
    flat = np.ascontiguousarray(lf.views.reshape(9, 24, 32, 3))
    mm = np.lib.format.open_memmap(tmp_path / "views.npy", mode="w+", dtype=np.uint8, shape=flat.shape)
    mm[:] = flat
    mm.flush()
    opts = EncodeOptions(params={"quant": 6})
    ref = b"".join(bytes(x) for _, x in RlfcCodec().encode(
        LightField(views=lf.views, positions=grid_positions(3, 3)), opts).sections)
    for src in (da.from_array(flat, chunks=(1, 24, 32, 3)), np.load(tmp_path / "views.npy", mmap_mode="r")):
        blob = b"".join(bytes(x) for _, x in RlfcCodec().encode(from_array(src, grid=(3, 3)), opts).sections)
        assert blob == ref
    # profiles that need every view at once read the array whole
    enc = RlfcCodec().encode(from_array(flat, grid=(3, 3)), EncodeOptions(profile="dcp", params={"quant": 6}))
    assert enc.decoded.shape == lf.views.shape


def test_cli_encodes_an_npy_array_of_views(tmp_path, capsys):
    import json

    from formats import open_decoder, open_lfc
    from formats.cli import main

    lf = smooth_lf(rows=3, cols=4, h=20, w=28)
    np.save(tmp_path / "views.npy", lf.views.reshape(12, 20, 28, 3))
    out = tmp_path / "a.lfc"
    assert main(["encode", str(tmp_path / "views.npy"), str(out), "--grid", "3x4", "--lossless", "--json",
                 "--quiet"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["exact"] and rep["views"] == 12
    with open_lfc(out) as f:
        assert (open_decoder(f).decode_all() == lf.views).all()
    np.save(tmp_path / "f.npy", np.zeros((4, 5, 6), np.float64))
    assert main(["encode", str(tmp_path / "f.npy"), str(tmp_path / "b.lfc"), "--quiet"]) == 2
    assert "uint8 or uint16" in capsys.readouterr().err


def test_a_list_of_views_is_stacked_and_bad_grids_are_scene_errors():
    """A list of same-shape views works like their stack; mixed shapes, a negative or float grid
    and a non-array are SceneErrors that say so (a list used to read as 'shape ()', and a grid of
    (-5, -5) passed the R·C = N check)."""
    v = np.arange(4 * 6 * 5 * 3, dtype=np.uint8).reshape(4, 6, 5, 3)
    assert (from_array(list(v), grid=(2, 2)).views[1, 0] == v[2]).all()
    for arr, grid, why in ((list(v[:1]) + [v[1, :3]], (1, 2), "one shape"), (v, (-2, -2), "positive"),
                           (v, (2.0, 2), "positive"), ({}, (2, 2), "got dict")):
        with pytest.raises(SceneError, match=why):
            from_array(arr, grid=grid)
