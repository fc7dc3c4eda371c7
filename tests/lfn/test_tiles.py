"""Tile sets of light field networks over camera space (lfn_stream.tiles)."""
import json
import shutil

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from formats.cli import main
from formats.codec_api import EncodeOptions
from formats.errors import FormatError, LfcError, ParameterError
from formats.lfcfile import open_lfc
from lfn_stream import LfnRenderer
from lfn_stream.codec import encode_tiles
from lfn_stream.tiles import (FORMAT_ID, blend_weights, open_tiles, partition_cameras, read_manifest,
                              tile_file_names)
from tests.conftest import ROOT
from tests.rlfc.helpers import smooth_lf

TINY = {"depth": 2, "min_neurons": 4, "max_neurons": 8, "occupancy_neurons": 0, "steps": 4, "batch": 128,
        "resolution": 0}


def _grid(rows=4, cols=6):
    y, x = np.mgrid[0:rows, 0:cols].astype(np.float64)
    return np.stack([x.ravel(), y.ravel(), np.zeros(rows * cols)], 1)


def test_partition_is_deterministic_and_covers_every_camera_with_its_band():
    pos = _grid()
    c1, m1 = partition_cameras(pos, 4, band=0.5)
    c2, m2 = partition_cameras(pos.copy(), 4, band=0.5)
    assert np.array_equal(c1, c2) and all(np.array_equal(a, b) for a, b in zip(m1, m2))
    assert len(c1) == 4
    # every camera trains the tile nearest to it, and every tile whose blend reaches it
    for i, p in enumerate(pos):
        w = blend_weights(c1, p, 0.5)
        assert {j for j in range(4) if i in m1[j]} == set(np.flatnonzero(w > 0))
        assert i in m1[int(np.argmin(np.linalg.norm(c1 - p, axis=1)))]
    # band 0: each camera in exactly one tile (ties aside); more tiles than cameras: one per camera
    _, m0 = partition_cameras(pos, 4, band=0.0)
    assert sum(len(m) for m in m0) == len(pos)
    c, m = partition_cameras(pos[:3], 8)
    assert len(c) == 3 and all(i in m[int(np.argmin(np.linalg.norm(c - pos[i], axis=1)))] for i in range(3))
    for bad in (0, 65, 2.5, True):
        with pytest.raises(ParameterError):
            partition_cameras(pos, bad)
    with pytest.raises(ParameterError):
        partition_cameras(pos, 2, band=float("nan"))


def test_blend_weights_sum_to_one_are_continuous_and_local():
    c = np.array([[0.0, 0, 0], [2.0, 0, 0], [0.0, 2, 0]])
    assert np.array_equal(blend_weights(c, c[1], 0.5), [0.0, 1.0, 0.0])       # at a centre: that tile alone
    prev = None
    for x in np.linspace(0, 2, 401):                                            # along the line between two tiles
        w = blend_weights(c, np.array([x, 0.0, 0.0]), 0.5)
        assert abs(w.sum() - 1) < 1e-12 and (w >= 0).all()
        if prev is not None:
            assert np.abs(w - prev).max() < 0.05                                  # no jump
        prev = w
    mid = blend_weights(c, np.array([1.0, 0.0, 0.0]), 0.5)
    assert mid[0] == pytest.approx(mid[1]) and mid[2] == 0                       # tile 2 is beyond the band


@pytest.fixture(scope="module")
def tileset(tmp_path_factory):
    d = tmp_path_factory.mktemp("tiles")
    lf = smooth_lf(rows=3, cols=4, h=12, w=12)
    rep = encode_tiles(lf, EncodeOptions(params={**TINY, "tiles": 3, "holdout": 4}), d / "s.json")
    return d, lf, rep


def test_tile_set_files_are_ordinary_lfn_streams_and_render_as_a_blend(tileset):
    d, lf, rep = tileset
    names = tile_file_names(d / "s.json", 3)
    assert [t["file"] for t in rep["tiles"]] == names == ["s.tile00.lfc", "s.tile01.lfc", "s.tile02.lfc"]
    m = json.loads((d / "s.json").read_text())
    assert m["format"] == FORMAT_ID and len(m["tiles"]) == 3
    assert rep["bytes"] == sum((d / n).stat().st_size for n in names) + (d / "s.json").stat().st_size
    assert rep["heldout_views"] == 3 and np.isfinite(rep["psnr_heldout"])
    # a training view trains every tile whose blend reaches it
    train = sorted(set(range(12)) - {2, 6, 10})
    assert sorted(set(v for t in m["tiles"] for v in t["views"])) == train
    with open_tiles(d / "s.json", device="cpu") as r:
        assert (r.rows, r.cols, r.height, r.width, r.channels) == (3, 4, 12, 12, 3)
        pose = r.grid_pose(1.0, 1.5)
        w = r.weights(pose)
        assert abs(sum(w.values()) - 1) < 1e-12
        got = r.render_pose(pose, 8.0, 1.0)
        want = sum(np.float32(wj) * r.tile(j).render_pose(pose, 8.0, 1.0) for j, wj in w.items())
        assert np.allclose(got, want, atol=1e-6) and got.shape == (12, 12, 4)
        px = r.to_pixels(got)
        assert px.shape == (12, 12, 3) and px.dtype == np.uint8
        assert r.prefix_bytes(8.0) <= rep["bytes"]
        # each tile carries its per-scale display ladders; the set shows the smallest tile's choice
        for sc in (0.25, 1.0, None):
            assert r.display_neurons_at(sc) == min(r.tile(j).display_neurons_at(sc) for j in range(3))
        assert all(len(r.tile(j).display_scales) == 4 for j in range(3))
    for n in names:                                # each tile opens on its own, as any LFN file
        with open_lfc(str(d / n)) as f:
            t = LfnRenderer(f, device="cpu")
            assert f.meta["config"]["tile"]["count"] == 3 and t.cfg.max_neurons == 8


def test_tile_sets_render_foveated_frames_as_a_blend(tileset):
    """render_pose_lod_mip on a tile set: the blend (render_pose's weights) of each tile's own
    foveated frame; where the map is the full network, the blend of the tiles' full renders."""
    d, lf, _ = tileset
    with open_tiles(d / "s.json", device="cpu") as r:
        pose = next(p for p in (r.grid_pose(a, b) for a in np.linspace(0, 2, 9) for b in np.linspace(0, 3, 13))
                    if len(r.weights(p)) >= 2)               # a camera between tiles
        w = r.weights(pose)
        lod = r.foveation_map((3.0, 8.0), dither=False, scale=2.0)
        got = r.render_pose_lod_mip(pose, lod)
        want = sum(np.float32(wj) * r.tile(j).render_pose_lod_mip(pose, lod) for j, wj in w.items())
        assert got.shape == (24, 24, 4) and np.allclose(got, want, atol=1e-6)
        full = r.render_pose(pose, float(r.neurons), 2.0)
        fovea = lod == r.neurons
        assert fovea.sum() >= 4 and np.allclose(got[fovea], full[fovea], atol=1e-6)
        assert not np.allclose(got, full, atol=1e-3)          # coarser networks away from the gaze
        assert np.allclose(r.render_pose_lod_mip(pose, np.full((12, 12), 8.0)), r.render_pose(pose, 8.0, 1.0),
                           atol=1e-6)


def test_tile_set_streams_over_http(tileset):
    from formats.serve import FileServer

    d, lf, _ = tileset
    with open_tiles(d / "s.json", device="cpu") as r:
        pose = r.pose(1, 1)
        local = r.render_pose(pose, 6.5, 1.0)
    with FileServer(d) as srv:
        with open_tiles(srv.url_of("s.json"), device="cpu", cache_bytes=1 << 16) as r:
            remote = r.render_pose(pose, 6.5, 1.0)
            used = set(r.weights(pose))
            assert set(r._tiles) == used | {0}          # only the tiles the camera blends (and tile 0) opened
            held = sum(t.file.container._src.cached_bytes for t in r._tiles.values())
            assert held <= 1 << 16                        # the budget is the whole set's
    assert np.array_equal(local, remote)


def test_cli_trains_and_renders_a_tile_set(tmp_path, capsys):
    out = tmp_path / "t.json"
    args = ["--depth", "2", "--min-neurons", "4", "--max-neurons", "8", "--steps", "3", "--batch", "128",
            "--resolution", "16", "--quiet"]
    assert main(["train", str(ROOT / "samples" / "dino_crop"), str(out), "--tiles", "2", "--json", *args]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert len(rep["tiles"]) == 2 and rep["heldout_views"] == 20 and (tmp_path / "t.tile01.lfc").exists()
    assert main(["render", str(out), str(tmp_path / "v.png"), "--at", "4,3.5", "--quiet"]) == 0
    assert main(["render", str(out), str(tmp_path / "q.png"), "--quilt", "2x1", "--level", "1", "--quiet"]) == 0
    assert main(["render", str(out), str(tmp_path / "turn"), "--path", "turn:2", "--level", "2", "--quiet"]) == 0
    from formats.imageio import read_image
    assert read_image(tmp_path / "v.png").shape == (128, 160, 3)
    assert len(list((tmp_path / "turn").glob("*.png"))) == 2
    # decode: the captured views rendered by the blend, as render gives them at those cameras
    # (decode used to read the manifest as an .lfc file: "wrong magic")
    assert main(["render", str(out), str(tmp_path / "c.png"), "--at", "4,3", "--level", "1", "--quiet"]) == 0
    assert main(["decode", str(out), str(tmp_path / "all"), "--level", "1", "--quiet"]) == 0
    assert len(list((tmp_path / "all").glob("r*_c*.png"))) == 81 and (tmp_path / "all" / "scene.json").exists()
    assert (read_image(tmp_path / "all" / "r04_c03.png") == read_image(tmp_path / "c.png")).all()
    assert main(["decode", str(out), "--view", "4,3", "--out", str(tmp_path / "one.npy"), "--level", "1",
                 "--quiet"]) == 0
    assert (np.load(tmp_path / "one.npy") == read_image(tmp_path / "c.png")).all()
    capsys.readouterr()
    assert main(["decode", str(out), "--block", "0,0,0,0", "--out", str(tmp_path / "b.npy")]) == 2
    assert "block random access" in capsys.readouterr().err
    # a tile set needs a .json manifest; a single file cannot hold one
    capsys.readouterr()
    assert main(["train", str(ROOT / "samples" / "dino_crop"), str(tmp_path / "t.lfc"), "--tiles", "2", *args]) == 2
    assert "manifest named *.json" in capsys.readouterr().err
    assert main(["render", str(out), str(tmp_path / "f.png"), "--focus", "1", "--quiet"]) == 2
    capsys.readouterr()
    # foveated: the blend of the tiles' foveated frames, as the library gives it
    assert main(["render", str(out), str(tmp_path / "g.png"), "--at", "4,3.5", "--gaze", "40,60", "--quiet"]) == 0
    with open_tiles(out, device="cpu") as r:
        pose = r.grid_pose(4, 3.5)
        want = r.to_pixels(r.render_pose_lod_mip(pose, r.foveation_map((40, 60), dither=False)))
    assert (read_image(tmp_path / "g.png") == want).all()
    for extra in (["--gaze", "4,4", "--fast"], ["--fast"]):
        assert main(["render", str(out), str(tmp_path / "f.png"), *extra, "--quiet"]) == 2
        assert "a tile set blends several" in capsys.readouterr().err and not (tmp_path / "f.png").exists()
    assert main(["info", str(out), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["tiles"] == 2
    # a single file is not written under a manifest's name; --tile-band needs --tiles
    assert main(["train", str(ROOT / "samples" / "dino_crop"), str(tmp_path / "one.json"), *args]) == 2
    assert "name a single file" in capsys.readouterr().err and not (tmp_path / "one.json").exists()
    assert main(["train", str(ROOT / "samples" / "dino_crop"), str(tmp_path / "one.lfc"), "--tile-band", "1",
                 *args]) == 2
    assert "goes with --tiles" in capsys.readouterr().err


@pytest.mark.parametrize("text, needle", [
    ("not json", "not a tile manifest"),
    ('{"format": "other"}', "not a tile manifest"),
    ('{"format": "lfcodec-lfn-tiles", "version": 9, "tiles": []}', "version 9"),
    ('{"format": "lfcodec-lfn-tiles", "version": 1, "tiles": []}', "1..64"),
    ('{"format": "lfcodec-lfn-tiles", "version": 1, "band": -1, "tiles": []}', "band"),
    ('{"format": "lfcodec-lfn-tiles", "version": 1, "tiles": [{"file": "../x.lfc", "centre": [0, 0, 0]}]}', "relative"),
    ('{"format": "lfcodec-lfn-tiles", "version": 1, "tiles": [{"file": "/etc/x.lfc", "centre": [0, 0, 0]}]}',
     "relative"),
    ('{"format": "lfcodec-lfn-tiles", "version": 1, "tiles": [{"file": "http://h/x.lfc", "centre": [0, 0, 0]}]}',
     "relative"),
    ('{"format": "lfcodec-lfn-tiles", "version": 1, "tiles": [{"file": "a.lfc", "centre": [0, 1e999, 0]}]}', "centre"),
    ('{"format": "lfcodec-lfn-tiles", "version": 1, "tiles": [{"file": "a.lfc", "centre": [0, 0]}]}', "centre"),
])
def test_hostile_manifests_are_format_errors(text, needle):
    with pytest.raises(FormatError, match=needle):
        read_manifest(text.encode(), "m.json")


def test_missing_or_mismatched_tiles_are_typed_errors(tileset, tmp_path, capsys):
    d, lf, _ = tileset
    for n in ("s.json", "s.tile00.lfc", "s.tile01.lfc", "s.tile02.lfc"):
        shutil.copy(d / n, tmp_path / n)
    (tmp_path / "s.tile01.lfc").write_bytes(b"garbage")
    with open_tiles(tmp_path / "s.json", device="cpu") as r:          # tile 0 opens; tile 1 fails when used
        with pytest.raises(LfcError):
            r.tile(1)
    # a tile of another scene's size
    other = tmp_path / "o"
    other.mkdir()
    encode_tiles(smooth_lf(rows=3, cols=4, h=16, w=12), EncodeOptions(params={**TINY, "tiles": 2}), other / "s.json")
    shutil.copy(other / "s.tile01.lfc", tmp_path / "s.tile01.lfc")
    with open_tiles(tmp_path / "s.json", device="cpu") as r:
        with pytest.raises(FormatError, match="differ"):
            r.tile(1)
    (tmp_path / "s.tile00.lfc").unlink()
    with pytest.raises(LfcError):
        open_tiles(tmp_path / "s.json")
    assert main(["render", str(tmp_path / "s.json"), str(tmp_path / "x.png"), "--quiet"]) == 2
    assert main(["render", str(tmp_path / "none.json"), str(tmp_path / "x.png"), "--quiet"]) == 2
    assert "no such tile manifest" in capsys.readouterr().err


@settings(max_examples=300, deadline=None)
@given(st.one_of(st.binary(max_size=200),
                 st.recursive(st.none() | st.booleans() | st.floats() | st.integers() | st.text(max_size=20),
                              lambda c: st.lists(c, max_size=4) | st.dictionaries(st.text(max_size=8), c, max_size=4),
                              max_leaves=20).map(lambda o: json.dumps(o).encode()),
                 st.fixed_dictionaries({"format": st.just(FORMAT_ID), "version": st.just(1),
                                        "band": st.floats() | st.integers(),
                                        "tiles": st.lists(st.fixed_dictionaries({
                                            "file": st.text(max_size=12),
                                            "centre": st.lists(st.floats() | st.integers(), max_size=4)}),
                                            max_size=3)}).map(lambda o: json.dumps(o).encode())))
def test_any_manifest_bytes_read_or_fail_with_a_format_error(data):
    try:
        m = read_manifest(data, "m.json")
    except FormatError:
        return
    assert 1 <= len(m["files"]) <= 64 and np.isfinite(m["centres"]).all() and 0 <= m["band"] <= 4
    assert all(".." not in f.split("/") and not f.startswith("/") for f in m["files"])
