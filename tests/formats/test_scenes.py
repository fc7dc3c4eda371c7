"""Scene readers: every layout on synthesized folders, the shared real scenes, and bad input."""
import json

import numpy as np
import pytest

from formats.errors import LfcError, SceneError
from formats.imageio import read_image, write_image
from formats.scenes import read_scene, write_views
from tests.conftest import shared_scene


def _img(h=6, w=8, c=3, dtype=np.uint8, seed=0):
    rng = np.random.default_rng(seed)
    return rng.integers(0, np.iinfo(dtype).max, (h, w, c), endpoint=True).astype(dtype)


def _grid(tmp_path, rows=2, cols=3, **kw):
    (tmp_path / "v").mkdir()
    imgs = {}
    for r in range(rows):
        for c in range(cols):
            imgs[r, c] = _img(seed=r * 10 + c, **kw)
            write_image(tmp_path / "v" / f"{r}_{c}.png", imgs[r, c])
    (tmp_path / "scene.json").write_text(json.dumps(
        {"layout": "grid", "rows": rows, "cols": cols, "views": "v/{row}_{col}.png", "baseline": None, "focal_px": None}))
    return imgs


def test_grid_scene(tmp_path):
    imgs = _grid(tmp_path)
    lf = read_scene(tmp_path)
    assert lf.views.shape == (2, 3, 6, 8, 3) and lf.layout == "grid"
    assert (lf.views[1, 2] == imgs[1, 2]).all()
    assert lf.focal == (8.0, 8.0) and "baseline=1" in lf.meta["assumed"]
    assert np.allclose(lf.positions[1, 2], [2, -1, 0])
    lf2 = read_scene(tmp_path, baseline=0.5, focal=100)
    assert lf2.focal == (100, 100) and np.allclose(lf2.positions[1, 2], [1, -0.5, 0])


@pytest.mark.parametrize("dtype,c", [(np.uint16, 3), (np.uint8, 1), (np.uint8, 4), (np.uint16, 1)])
def test_depths_and_channels(tmp_path, dtype, c):
    imgs = _grid(tmp_path, dtype=dtype, c=c)
    lf = read_scene(tmp_path)
    assert lf.views.dtype == dtype and lf.channels == c
    assert (lf.views[0, 1] == imgs[0, 1]).all()


def test_hci_layout(tmp_path):
    for i in range(9):
        write_image(tmp_path / f"input_Cam{i:03d}.png", _img(seed=i))
    (tmp_path / "license.txt").write_text("x")
    lf = read_scene(tmp_path)
    assert lf.views.shape[:2] == (3, 3)
    assert (lf.views[1, 2] == _img(seed=5)).all()


def test_hci_missing_view(tmp_path):
    for i in [0, 1, 2, 3, 5, 6, 7, 8]:
        write_image(tmp_path / f"input_Cam{i:03d}.png", _img(seed=i))
    with pytest.raises(SceneError, match="input_Cam"):
        read_scene(tmp_path)


def test_stanford_layout(tmp_path):
    for r in range(2):
        for c in range(2):
            write_image(tmp_path / f"out_{r:02d}_{c:02d}_-100.5_200.25.png", _img(seed=r * 2 + c))
    lf = read_scene(tmp_path)
    assert lf.views.shape[:2] == (2, 2) and (lf.views[1, 0] == _img(seed=2)).all()
    (tmp_path / "out_01_01_-100.5_200.25.png").unlink()
    with pytest.raises(SceneError, match="missing"):
        read_scene(tmp_path)


def test_llff_layout(tmp_path):
    (tmp_path / "images").mkdir()
    n = 3
    for i in range(n):
        write_image(tmp_path / "images" / f"img{i:03d}.png", _img(seed=i))
    pb = np.zeros((n, 17))
    for i in range(n):
        m = np.zeros((3, 5))
        m[:, :3] = np.eye(3)
        m[:, 3] = [i, 0, 0]
        m[:, 4] = [12, 16, 20]          # original capture 16 px wide, focal 20
        pb[i, :15] = m.reshape(-1)
    np.save(tmp_path / "poses_bounds.npy", pb)
    lf = read_scene(tmp_path)
    assert lf.views.shape[:2] == (1, 3) and lf.layout == "posed"
    assert lf.focal[0] == pytest.approx(20 * 8 / 16)
    # LLFF (down, right, back) -> OpenGL (right, up, back)
    assert np.allclose(lf.c2w[0, 0, :3, :3], [[0, -1, 0], [1, 0, 0], [0, 0, 1]])
    np.save(tmp_path / "poses_bounds.npy", pb[:2])
    with pytest.raises(SceneError, match="2 poses"):
        read_scene(tmp_path)
    # not NumPy, pickled objects, a header claiming far more rows than the file holds: each says
    # what it is (numpy's message advised loading the pickle with allow_pickle), nothing allocated
    pbp = tmp_path / "poses_bounds.npy"
    pbp.write_bytes(b"garbage bytes here")
    with pytest.raises(SceneError, match="not a NumPy .npy file"):
        read_scene(tmp_path)
    np.save(pbp, np.array(["a", "b"], dtype=object), allow_pickle=True)
    with pytest.raises(SceneError, match="Python objects .*does not load") as e:
        read_scene(tmp_path)
    assert "allow_pickle" not in str(e.value)
    hdr = "{'descr': '<f8', 'fortran_order': False, 'shape': (1000000000000, 17), }"
    hdr += " " * (118 - len(hdr)) + "\n"
    pbp.write_bytes(b"\x93NUMPY\x01\x00" + len(hdr).to_bytes(2, "little") + hdr.encode() + bytes(64))
    with pytest.raises(SceneError, match="shorter than the array its .npy header describes"):
        read_scene(tmp_path)


def test_transforms_layout(tmp_path):
    (tmp_path / "train").mkdir()
    frames = []
    for i in range(2):
        write_image(tmp_path / "train" / f"r_{i}.png", _img(c=4, seed=i))
        frames.append({"file_path": f"./train/r_{i}", "transform_matrix": np.eye(4).tolist()})
    (tmp_path / "transforms_train.json").write_text(json.dumps({"camera_angle_x": 0.5, "frames": frames}))
    lf = read_scene(tmp_path)
    assert lf.views.shape == (1, 2, 6, 8, 4) and lf.has_alpha
    assert lf.focal[0] == pytest.approx(4 / np.tan(0.25))
    lf2 = read_scene(tmp_path / "transforms_train.json")
    assert (lf2.views == lf.views).all()


def test_mixed_sizes_and_channels(tmp_path):
    _grid(tmp_path)
    write_image(tmp_path / "v" / "1_1.png", _img(h=7))
    with pytest.raises(SceneError, match="1_1.png"):
        read_scene(tmp_path)
    write_image(tmp_path / "v" / "1_1.png", _img(c=4))
    with pytest.raises(SceneError, match="channels"):
        read_scene(tmp_path)


def test_missing_view(tmp_path):
    _grid(tmp_path)
    (tmp_path / "v" / "0_2.png").unlink()
    with pytest.raises(SceneError, match="missing view"):
        read_scene(tmp_path)


def test_unreadable_image(tmp_path):
    _grid(tmp_path)
    (tmp_path / "v" / "0_1.png").write_bytes(b"\x89PNG\r\n\x1a\n garbage")
    with pytest.raises(SceneError, match="0_1.png"):
        read_scene(tmp_path)


def test_empty_and_nonimage_folders(tmp_path):
    with pytest.raises(SceneError, match="empty"):
        read_scene(tmp_path)
    (tmp_path / "notes.txt").write_text("hello")
    (tmp_path / "data.csv").write_text("1,2")
    with pytest.raises(SceneError, match="no recognizable"):
        read_scene(tmp_path)
    with pytest.raises(SceneError, match="no such"):
        read_scene(tmp_path / "nope")
    with pytest.raises(SceneError, match="folder"):
        read_scene(tmp_path / "notes.txt")


def test_bad_scene_json(tmp_path):
    (tmp_path / "scene.json").write_text("{not json")
    with pytest.raises(SceneError, match="JSON"):
        read_scene(tmp_path)
    (tmp_path / "scene.json").write_text('{"rows": 2}')
    with pytest.raises(SceneError, match="rows, cols and views"):
        read_scene(tmp_path)


def test_write_views_roundtrip_16bit(tmp_path):
    v = np.stack([np.stack([_img(dtype=np.uint16, seed=s) for s in range(2)])])
    paths = write_views(tmp_path / "out", v)
    assert [p.name for p in paths] == ["r00_c00.png", "r00_c01.png"]
    back = read_image(paths[1])
    assert back.dtype == np.uint16 and (back == v[0, 1]).all()


@pytest.mark.parametrize("name,shape", [
    ("hci_antinous", (9, 9, 512, 512, 3)), ("lytro_dino_2067", (9, 9, 304, 432, 3)),
    ("llff_statue", (1, 27, 960, 540, 3)), ("mitsuba_objects_360", (1, 100, 256, 256, 4))])
def test_shared_scenes(name, shape):
    lf = read_scene(shared_scene(name))
    assert lf.views.shape == shape and lf.views.dtype == np.uint8
    if lf.layout == "posed":
        rot = lf.c2w[0, :, :3, :3]
        assert np.allclose(rot @ rot.transpose(0, 2, 1), np.eye(3), atol=1e-4)


def test_errors_are_lfc_errors():
    assert issubclass(SceneError, LfcError)


def _grid_scene(tmp_path, pattern="views/r{row:02d}_c{col:02d}.png", rows=2, cols=2, **extra):
    from formats.imageio import write_image

    (tmp_path / "views").mkdir(exist_ok=True)
    for r in range(rows):
        for c in range(cols):
            write_image(tmp_path / "views" / f"r{r:02d}_c{c:02d}.png", _img(seed=r * cols + c))
    (tmp_path / "scene.json").write_text(json.dumps({"layout": "grid", "rows": rows, "cols": cols, "views": pattern,
                                                     **extra}))
    return tmp_path


@pytest.mark.parametrize("pattern,needle", [
    ("{row:>1000000000}.png", "may only use"), ("{row.__class__}.png", "may only use"),
    ("{0}.png", "may only use"), ("static.png", "names no"), ("{row!r}.png", "may only use"),
])
def test_hostile_view_patterns(tmp_path, pattern, needle):
    _grid_scene(tmp_path, pattern=pattern)
    with pytest.raises(SceneError, match=needle):
        read_scene(tmp_path)


def test_paths_outside_the_scene_are_refused(tmp_path):
    from formats.imageio import write_image

    outside = tmp_path / "secret"
    outside.mkdir()
    write_image(outside / "x.png", _img())
    scene = tmp_path / "scene"
    scene.mkdir()
    _grid_scene(scene, pattern="../secret/x.png{row:.0}{col:.0}", rows=1, cols=1)
    with pytest.raises(SceneError):
        read_scene(scene)
    # a symlink leading out is followed and refused too
    (scene / "views").mkdir(exist_ok=True)
    (scene / "views" / "link.png").symlink_to(outside / "x.png")
    (scene / "scene.json").write_text(json.dumps({"rows": 1, "cols": 1, "views": "views/link{row:.0}.png"}))
    with pytest.raises(SceneError):
        read_scene(scene)
    # transforms.json file_path with .. or an absolute path
    frames = [{"file_path": str(outside / "x"), "transform_matrix": np.eye(4).tolist()}]
    (scene / "transforms.json").write_text(json.dumps({"camera_angle_x": 0.5, "frames": frames}))
    (scene / "scene.json").unlink()
    with pytest.raises(SceneError, match="outside the scene"):
        read_scene(scene)
    lf = read_scene(scene, allow_outside=True)            # the user can opt in
    assert lf.rows * lf.cols == 1


def test_declared_counts_and_sizes_are_bounded_before_reading(tmp_path):
    from formats.limits import Limits

    _grid_scene(tmp_path, rows=2, cols=2)
    (tmp_path / "scene.json").write_text(json.dumps({"rows": 10 ** 8, "cols": 1, "views": "views/r{row:02d}.png"}))
    with pytest.raises(SceneError, match="exceed"):
        read_scene(tmp_path)
    _grid_scene(tmp_path, rows=2, cols=2)
    with pytest.raises(SceneError, match="exceed the limit"):
        read_scene(tmp_path, limits=Limits(max_view_pixels=10))


@pytest.mark.parametrize("cfg,needle", [
    ({"camera_angle_x": 0}, "camera_angle_x"), ({"camera_angle_x": "wide"}, "camera_angle_x"),
    ({"fl_x": -3}, "fl_x"), ({"camera_angle_x": 0.5, "cx": float("nan")}, "cx"),
    ({"camera_angle_x": 0.5, "frames": [{"file_path": 3}]}, "file_path"),
    ({"camera_angle_x": 0.5, "frames": [{"file_path": "a"}]}, "transform_matrix"),
    ({"camera_angle_x": 0.5, "frames": "x"}, "frames"),
])
def test_transforms_fields_give_typed_errors(tmp_path, cfg, needle):
    from formats.imageio import write_image

    write_image(tmp_path / "a.png", _img())
    full = {"frames": [{"file_path": "a", "transform_matrix": np.eye(4).tolist()}], **cfg}
    (tmp_path / "transforms.json").write_text(json.dumps(full))
    with pytest.raises(SceneError, match=needle):
        read_scene(tmp_path)


def test_nan_camera_matrix_is_refused(tmp_path):
    from formats.imageio import write_image

    write_image(tmp_path / "a.png", _img())
    m = np.eye(4)
    m[0, 3] = float("nan")
    (tmp_path / "transforms.json").write_text(json.dumps({"camera_angle_x": 0.5, "frames": [
        {"file_path": "a", "transform_matrix": m.tolist()}]}))
    with pytest.raises(SceneError, match="NaN"):
        read_scene(tmp_path)


def test_bad_camera_matrices_are_refused_before_any_view_is_read(tmp_path, monkeypatch):
    """A frame without a matrix, or one that is not 4x4 numbers: a SceneError saying which, and
    no image read first (the reader used to load every view, then fail on numpy's message)."""
    import formats.scenes.posed as posed

    reads = []
    monkeypatch.setattr(posed, "load_views", lambda *a, **k: reads.append(1))
    for frames, needle in (([{"file_path": "a"}, {"file_path": "a", "transform_matrix": np.eye(4).tolist()}],
                            "frame 0 has no transform_matrix"),
                           ([{"file_path": "a", "transform_matrix": [[1, 2], [3]]}], "4x4 numbers in every frame")):
        (tmp_path / "transforms.json").write_text(json.dumps({"camera_angle_x": 0.5, "frames": frames}))
        with pytest.raises(SceneError, match=needle):
            read_scene(tmp_path)
    assert reads == []


# -- views left in their files (read_scene(lazy=True); what `lfcodec encode` reads) -----------

def _hci(tmp_path, n=9, **kw):
    for i in range(n):
        write_image(tmp_path / f"input_Cam{i:03d}.png", _img(seed=i, **kw))


def _stanford(tmp_path, **kw):
    for r in range(2):
        for c in range(2):
            write_image(tmp_path / f"out_{r:02d}_{c:02d}_-100.5_200.25.png", _img(seed=r * 2 + c, **kw))


def _folder(tmp_path, **kw):
    for i in range(6):
        write_image(tmp_path / f"img{i}.png", _img(seed=i, **kw))


@pytest.mark.parametrize("make,grid", [(_grid, None), (_hci, None), (_stanford, None), (_folder, (2, 3))])
@pytest.mark.parametrize("dtype,c", [(np.uint8, 3), (np.uint16, 3), (np.uint8, 1), (np.uint8, 4), (np.uint16, 2)])
def test_lazy_grid_readers_decode_nothing_until_asked_and_give_the_same_views(tmp_path, make, grid, dtype, c):
    make(tmp_path, dtype=dtype, c=c)
    eager = read_scene(tmp_path, grid=grid)
    lazy = read_scene(tmp_path, grid=grid, lazy=True)
    files = lazy.views.arr
    assert isinstance(eager.views, np.ndarray) and files.decodes == 0
    assert lazy.views.shape == eager.views.shape and lazy.views.dtype == eager.views.dtype == dtype
    assert (lazy.focal, lazy.layout, lazy.meta) == (eager.focal, eager.layout, eager.meta)
    assert np.array_equal(lazy.positions, eager.positions)
    r, cc = lazy.rows - 1, lazy.cols - 1
    assert np.array_equal(lazy.views[r, cc], eager.views[r, cc]) and files.decodes == 1
    assert np.array_equal(np.asarray(lazy.views), eager.views)


def test_a_lazy_view_changed_or_broken_after_opening_is_a_scene_error(tmp_path):
    import os

    _grid(tmp_path)
    lf = read_scene(tmp_path, lazy=True)
    write_image(tmp_path / "v" / "0_1.png", _img(seed=99))          # replaced under the reader
    os.utime(tmp_path / "v" / "0_1.png", ns=(1, 1))
    with pytest.raises(SceneError, match="0_1.png changed on disk"):
        lf.views[0, 1]
    with pytest.raises(SceneError, match="changed on disk"):
        np.asarray(lf.views)
    assert np.array_equal(lf.views[1, 1], _img(seed=11))            # the others still read
    p = tmp_path / "v" / "1_0.png"
    data = p.read_bytes()
    lf = read_scene(tmp_path, lazy=True)
    with open(p, "r+b") as f:                                        # same size and time, pixels cut
        f.seek(len(data) // 2)
        f.write(b"\0" * (len(data) - len(data) // 2))
    st = os.stat(p)
    os.utime(p, ns=(st.st_atime_ns, lf.views.arr.file(3).stamp[1]))
    with pytest.raises(SceneError, match="1_0.png"):
        lf.views[1, 0]


@pytest.mark.parametrize("opts,most", [({"target_psnr": 38}, 2), ({"target_bpp": 1.5}, 1), ({}, 1),
                                       ({"lossless": True}, 1)])
def test_an_encode_from_files_left_on_disk_writes_the_same_file(tmp_path, capsys, opts, most):
    """An encode from views left in their files gives the same bytes as one from the views in
    memory. Each view is decoded once where every pass codes every view (they are kept once
    read), at most twice under a PSNR search (its keys and sample kept; the others decoded again
    for the full pass); an encoder given views in memory keeps no copies."""
    from formats import EncodeOptions
    from formats.cli import main
    from rlfc import txencode
    from rlfc.codec import RlfcCodec
    from tests.rlfc.helpers import smooth_lf

    src = smooth_lf(rows=5, cols=5, h=32, w=40)
    for r in range(5):
        for c in range(5):
            write_image(tmp_path / f"input_Cam{r * 5 + c:03d}.png", src.views[r, c])
    opts = EncodeOptions(keep_decoded=False, **opts)
    held = []
    real = txencode.TxEncoder.hold
    txencode.TxEncoder.hold = lambda self, v: (real(self, v), held.append(len(self._hold)))[0]
    try:
        ref = RlfcCodec().encode(read_scene(tmp_path), opts)
        assert held and max(held) == 0                      # views in memory: nothing kept
        lazy = read_scene(tmp_path, lazy=True)
        enc = RlfcCodec().encode(lazy, opts)
    finally:
        txencode.TxEncoder.hold = real
    assert [(k, bytes(x)) for k, x in enc.sections] == [(k, bytes(x)) for k, x in ref.sections]
    assert 25 <= lazy.views.arr.decodes <= most * 25 and held[-1] == 0
    if "target_psnr" in opts.__dict__ and opts.target_psnr:
        assert 0 < held[-2] < 25                            # the search's keys and sample
        out = tmp_path / "out" / "a.lfc"
        out.parent.mkdir()
        assert main(["encode", str(tmp_path), str(out), "--target-psnr", "38", "--quiet", "--json"]) == 0
        rep = json.loads(capsys.readouterr().out)
        assert rep["psnr_rgb"] == pytest.approx(ref.summary["psnr_rgb"], abs=1e-9) and rep["target_met"]


def _with_chunk(png: bytes, kind: bytes, body: bytes) -> bytes:
    """``png`` with a chunk inserted after IHDR (CRC computed)."""
    import struct
    import zlib

    chunk = struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body) & 0xFFFFFFFF)
    return png[:33] + chunk + png[33:]


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
@pytest.mark.parametrize("c", [1, 2, 3, 4])
def test_plain_pngs_decode_as_openimageio_decodes_them(tmp_path, monkeypatch, dtype, c):
    """The libpng fast path (imagecodecs) gives OpenImageIO's samples for every plain PNG kind;
    PNGs with transparency or significant-bits chunks, and broken ones, go to OpenImageIO."""
    import formats.imageio as io

    im = _img(h=9, w=13, c=c, dtype=dtype, seed=c)
    p = tmp_path / "a.png"
    write_image(p, im)
    fast = io._plain_png(str(p), None)
    assert fast is not None and fast.dtype == dtype and np.array_equal(fast, im)
    monkeypatch.setattr(io, "_plain_png", lambda path, m: None)        # OpenImageIO alone
    assert np.array_equal(read_image(p), fast)
    monkeypatch.undo()
    oiio = io._oiio()
    inp = oiio.ImageInput.open(str(p))
    spec = inp.spec()
    inp.close()
    assert io.image_size(p) == (spec.height, spec.width, spec.nchannels, str(spec.format))
    with pytest.raises(SceneError, match="exceed the limit"):
        io._plain_png(str(p), 100)
    data = p.read_bytes()
    for kind, body in ((b"tRNS", b"\0\0" if c == 1 else b"\0\0\0\0\0\0"), (b"sBIT", bytes([8] * c))):
        q = tmp_path / f"{kind.decode()}.png"
        q.write_bytes(_with_chunk(data, kind, body))
        assert io._plain_png(str(q), None) is None
    q = tmp_path / "cut.png"
    q.write_bytes(data[:len(data) - 30])
    assert io._plain_png(str(q), None) is None
    with pytest.raises(SceneError, match="cut.png"):
        read_image(q)


def test_a_scene_of_plain_pngs_never_loads_openimageio(tmp_path):
    """Headers and pixels of plain PNGs come from the files and libpng (imagecodecs): reading
    such a scene costs no OpenImageIO (31 MiB resident)."""
    import subprocess
    import sys

    _hci(tmp_path)
    code = ("import sys; from formats.scenes import read_scene; lf = read_scene(sys.argv[1], lazy=True); "
            "lf.views[1, 1]; read_scene(sys.argv[1]); print('OpenImageIO' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code, str(tmp_path)], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and out.stdout.strip() == "False", out.stderr
