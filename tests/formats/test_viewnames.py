"""Original view file names (issue 15): recorded at encode, validated as untrusted input,
written back by `lfcodec decode --names original` with a layout file that encodes again."""
import base64
import json
import os
import zlib

import numpy as np
import pytest

from formats.cli import main
from formats.errors import FormatError
from formats.imageio import read_image, write_image
from formats.lfcfile import open_lfc
from formats.scenes import read_scene
from formats.viewnames import pack_names, unpack_names
from tests.rlfc.helpers import smooth_lf

BAD = [["../x.png", "b.png"], ["/etc/passwd", "b.png"], ["a\\b.png", "b.png"], ["c:x.png", "b.png"],
       ["x" * 201, "b.png"], ["A.png", "a.jpg"], ["a/./b.png", "b.png"], ["a//b.png", "b.png"],
       ["~/x.png", "b.png"], ["a\nb.png", "b.png"], ["1/2/3/4/5.png", "b.png"], ["", "b.png"], ["a.png"],
       ["a.png", 3], "a.png"]


@pytest.mark.parametrize("names", BAD)
def test_hostile_names_are_format_errors(names):
    text = base64.b64encode(zlib.compress(json.dumps(names).encode())).decode()
    with pytest.raises(FormatError):
        unpack_names(text, 2, "scene")


@pytest.mark.parametrize("text", ["not base64!", base64.b64encode(b"not zlib").decode(), 7, None,
                                  base64.b64encode(zlib.compress(b"[" * 100000)).decode(),
                                  base64.b64encode(zlib.compress(b" " * 10_000_000)).decode(),
                                  base64.b64encode(zlib.compress(b'["a.png","b.png"]')[:-3]).decode()])
def test_bad_names_z_is_a_format_error(text):
    with pytest.raises(FormatError):
        unpack_names(text, 2, "scene")


def test_names_round_trip_and_stay_small():
    names = [f"input_Cam{i:03d}.png" for i in range(81)]
    z = pack_names(names)
    assert unpack_names(z, 81, "s") == names and len(z) < 400


def _named_folder(root, names, lf):
    root.mkdir()
    for n, v in zip(names, lf.views.reshape(-1, *lf.views.shape[2:])):
        write_image(root / n, v)


def test_decode_original_names_round_trip(tmp_path, capsys):
    lf = smooth_lf(rows=2, cols=3, h=16, w=24)
    names = ["left_top.png", "mid_top.png", "right_top.png", "left_bot.png", "mid_bot.png", "right_bot.png"]
    _named_folder(tmp_path / "scene", names, lf)
    got = read_scene(tmp_path / "scene", grid=(2, 3))
    order = got.meta["view_names"]                             # natural name order, row-major
    assert sorted(order) == sorted(names)
    f = tmp_path / "a.lfc"
    assert main(["encode", str(tmp_path / "scene"), str(f), "--grid", "2x3", "--lossless", "--quiet"]) == 0
    assert main(["decode", str(f), str(tmp_path / "dec"), "--names", "original", "--quiet"]) == 0
    assert sorted(p.name for p in (tmp_path / "dec").iterdir()) == sorted(names + ["scene.json"])
    cfg = json.loads((tmp_path / "dec" / "scene.json").read_text())
    assert cfg["views"] == order
    for n in names:
        assert (read_image(tmp_path / "dec" / n) == read_image(tmp_path / "scene" / n)).all()
    again = read_scene(tmp_path / "dec")                        # the decoded folder encodes again
    assert again.meta["view_names"] == order and (again.views == got.views).all()
    # the default stays rRR_cCC.png
    assert main(["decode", str(f), str(tmp_path / "grid"), "--quiet"]) == 0
    assert (tmp_path / "grid" / "r01_c02.png").exists()


def _encoded_1x2(tmp_path, sub: str):
    """A 1×2 grid whose scene.json lists its views as SUB/v0.png, SUB/v1.png, encoded losslessly."""
    lf = smooth_lf(rows=1, cols=2, h=16, w=16)
    root = tmp_path / "scene"
    (root / sub).mkdir(parents=True)
    for c in range(2):
        write_image(root / sub / f"v{c}.png", lf.views[0, c])
    names = [f"{sub}/v0.png", f"{sub}/v1.png"]
    (root / "scene.json").write_text(json.dumps({"layout": "grid", "rows": 1, "cols": 2, "views": names}))
    assert read_scene(root).meta["view_names"] == names
    f = tmp_path / "a.lfc"
    assert main(["encode", str(root), str(f), "--lossless", "--quiet"]) == 0
    return f


def test_original_names_keep_subfolders_and_extension_becomes_png(tmp_path):
    f = _encoded_1x2(tmp_path, "views")
    assert main(["decode", str(f), str(tmp_path / "dec"), "--names", "original", "--quiet"]) == 0
    assert (tmp_path / "dec" / "views" / "v1.png").exists()


def test_names_are_confined_to_the_output_folder(tmp_path, capsys):
    f = _encoded_1x2(tmp_path, "sub")
    out, elsewhere = tmp_path / "out", tmp_path / "elsewhere"
    out.mkdir()
    elsewhere.mkdir()
    os.symlink(elsewhere, out / "sub")                          # out/sub leads outside the output folder
    assert main(["decode", str(f), str(out), "--names", "original", "--quiet"]) == 2
    assert "outside" in capsys.readouterr().err
    assert list(elsewhere.iterdir()) == []


def test_original_names_need_a_file_that_has_them(tmp_path, capsys):
    lf = smooth_lf(rows=2, cols=2, h=16, w=16)
    np.save(tmp_path / "v.npy", lf.views.reshape(4, 16, 16, 3))
    f = tmp_path / "a.lfc"
    assert main(["encode", str(tmp_path / "v.npy"), str(f), "--grid", "2x2", "--lossless", "--quiet"]) == 0
    assert "names_z" not in open_lfc(str(f)).meta["scene"]
    assert main(["decode", str(f), str(tmp_path / "dec"), "--names", "original", "--quiet"]) == 2
    assert "original names" in capsys.readouterr().err


@pytest.mark.parametrize("splits", [[["train", 3]], [["train", 2], ["train", 2]], [["../x", 4]], [["a", 0], ["b", 4]],
                                    [["a", True], ["b", 3]], "train", [["a", 2, 3]], [[1, 4]], [["a", 4.0]]])
def test_bad_splits_are_format_errors(splits):
    """A file's recorded splits are untrusted: distinct plain names, counts >= 1 covering every view."""
    from formats.lightfield import read_geometry

    g = {"rows": 1, "cols": 4, "height": 2, "width": 2, "channels": 3, "dtype": "uint8", "splits": splits}
    with pytest.raises(FormatError, match="splits"):
        read_geometry(g, "scene")
    assert read_geometry({**g, "splits": [["train", 3], ["test", 1]]}, "scene")["splits"] == [("train", 3), ("test", 1)]


def test_a_baseline_whose_grid_overflows_is_a_format_error():
    """Finite baseline, infinite camera positions (found by tools.fuzz seed 31 as a numpy overflow
    warning): refused before positions are built."""
    import warnings

    from formats.lightfield import read_geometry

    g = {"rows": 1, "cols": 4, "height": 2, "width": 2, "channels": 3, "dtype": "uint8", "baseline": [1e308, 1.0]}
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(FormatError, match="baseline"):
            read_geometry(g, "scene")
    assert read_geometry({**g, "baseline": [1e90, 1.0]}, "scene")["baseline"] == [1e90, 1.0]


@pytest.mark.parametrize("field", ["principal", "focal", "baseline"])
def test_booleans_are_not_numbers_in_geometry(field):
    """JSON false in a numeric field (found by tools.fuzz seed 31: the library read it as 0, the
    reference reader refused it) is a FormatError."""
    from formats.lightfield import read_geometry

    g = {"rows": 1, "cols": 4, "height": 2, "width": 2, "channels": 3, "dtype": "uint8", field: [1.0, False]}
    with pytest.raises(FormatError, match=field):
        read_geometry(g, "scene")
