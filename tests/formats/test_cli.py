"""The lfcodec CLI as a user runs it: encode → info → decode, and bad input."""
import json
import subprocess
import sys

import numpy as np
import pytest

from formats.cli import main
from formats.imageio import read_image
from formats.scenes import read_scene
from tests.conftest import ROOT

SAMPLE = ROOT / "samples" / "dino_crop"


@pytest.fixture(scope="module")
def encoded(tmp_path_factory):
    out = tmp_path_factory.mktemp("cli") / "dino.lfc"
    assert main(["encode", str(SAMPLE), str(out), "--quiet"]) == 0
    return out


def test_encode_json_report(tmp_path, capsys):
    out = tmp_path / "x.lfc"
    assert main(["encode", str(SAMPLE), str(out), "--quant", "6", "--json", "--quiet"]) == 0
    rep = json.loads(capsys.readouterr().out)
    for k in ("bytes", "bpp", "psnr_rgb", "psnr_ycocg", "ssim", "encode_s"):
        assert k in rep
    assert rep["bytes"] == out.stat().st_size
    assert rep["bpp"] == pytest.approx(8 * rep["bytes"] / (81 * 128 * 160))
    assert 35 < rep["psnr_rgb"] < 60 and 0.8 < rep["ssim"] <= 1


def test_target_psnr(tmp_path, capsys):
    out = tmp_path / "t.lfc"
    assert main(["encode", str(SAMPLE), str(out), "--target-psnr", "40", "--json", "--quiet"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert 40 <= rep["psnr_rgb"] < 40.6, rep["psnr_rgb"]
    assert len(rep["search"]) >= 5
    # the decoded file reaches the reported quality
    assert main(["decode", str(out), str(tmp_path / "v"), "--quiet"]) == 0
    lf = read_scene(SAMPLE)
    dec = np.stack([read_image(tmp_path / "v" / f"r{r:02d}_c{c:02d}.png") for r in range(9) for c in range(9)])
    from formats.metrics import psnr_rgb
    assert psnr_rgb(lf.views.reshape(dec.shape), dec) == pytest.approx(rep["psnr_rgb"], abs=1e-9)


def test_a_lossy_grid_report_measures_the_file_written(tmp_path, capsys, monkeypatch):
    """A lossy grid encode holds no decoded copy (``keep_decoded=False``): the --json report's
    figures are those of the file decoded a few views at a time (SSIM, YCoCg and per-view PSNR
    included); a lossless encode keeps the encoder's decoded views (its decoder's parse holds
    more than they do)."""
    import formats.cli_encode as cli
    from formats.lfcfile import open_lfc
    from formats.metrics import quality_report
    from formats.registry import open_decoder

    calls = []
    real = cli._quality_of_file
    monkeypatch.setattr(cli, "_quality_of_file", lambda *a, **k: calls.append(a[0]) or real(*a, **k))
    out = tmp_path / "q.lfc"
    assert main(["encode", str(SAMPLE), str(out), "--target-psnr", "38", "--json", "--quiet"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert calls == [out]
    lf = read_scene(SAMPLE)
    with open_lfc(out) as f:
        dec = open_decoder(f).decode_all()
    want = quality_report(lf.views, dec.reshape(lf.views.shape))
    for k, v in want.items():
        assert rep[k] == (pytest.approx(v, rel=1e-12) if isinstance(v, float) else v), k
    assert main(["encode", str(SAMPLE), str(tmp_path / "l.lfc"), "--lossless", "--quiet"]) == 0
    assert calls == [out]


def test_target_bpp(tmp_path, capsys):
    out = tmp_path / "b.lfc"
    assert main(["encode", str(SAMPLE), str(out), "--target-bpp", "1.0", "--json", "--quiet"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert 0.5 < rep["bpp"] <= 1.0
    # it is the best-quality point the search saw under the target
    feasible = [t for t in rep["search"] if t["bpp"] <= 1.0]
    assert rep["psnr_rgb"] == pytest.approx(max(t["psnr_rgb"] for t in feasible))


def test_lossless_json_has_no_infinity(tmp_path, capsys):
    assert main(["encode", str(SAMPLE), str(tmp_path / "l.lfc"), "--lossless", "--json", "--quiet"]) == 0
    text = capsys.readouterr().out
    rep = json.loads(text, parse_constant=lambda c: pytest.fail(f"non-JSON constant {c}"))
    assert rep["exact"] is True and rep["psnr_rgb"] is None


def test_info(encoded, capsys):
    assert main(["info", str(encoded), "--json", "--verify"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["codec"] == "rlfc" and rep["scene"]["rows"] == 9 and rep["verified"]
    # a grid encodes with the tx profile by default (--profile auto)
    assert rep["decoder"]["profile"] == "tx" and rep["decoder"]["levels"] == 1
    assert [s["name"] for s in rep["sections"]] == ["meta", "tx.layout", "tx.tables", "tx.maps", "tx.thumbs",
                                                     "tx.keyimg", "tx.index", "tx.blocks"]
    assert main(["info", str(encoded)]) == 0
    assert "tx.blocks" in capsys.readouterr().out


def test_decode_views_view_and_block(encoded, tmp_path, capsys):
    assert main(["decode", str(encoded), str(tmp_path / "all"), "--quiet"]) == 0
    files = sorted(p.name for p in (tmp_path / "all").iterdir() if p.suffix == ".png")
    assert len(files) == 81 and files[0] == "r00_c00.png" and files[-1] == "r08_c08.png"
    assert (tmp_path / "all" / "scene.json").is_file()
    assert main(["decode", str(encoded), str(tmp_path / "one"), "--view", "3,5", "--quiet"]) == 0
    one = read_image(tmp_path / "one" / "r03_c05.png")
    # without --quiet: one line saying what was written (one view, no layout file)
    assert main(["decode", str(encoded), str(tmp_path / "one_v"), "--view", "3,5"]) == 0
    said = capsys.readouterr().out
    assert "wrote 1 view(s) to" in said and "scene.json" not in said
    assert main(["decode", str(encoded), str(tmp_path / "all_v")]) == 0
    assert "wrote 81 view(s) and scene.json to" in capsys.readouterr().out
    assert (one == read_image(tmp_path / "all" / "r03_c05.png")).all()
    # --block ROW,COL,BY,BX: view (3,5), block row 2, block column 4 → pixels [32,48) x [64,80) (16-px blocks)
    assert main(["decode", str(encoded), "--block", "3,5,2,4", "--out", str(tmp_path / "b.npy"), "--quiet"]) == 0
    blk = np.load(tmp_path / "b.npy")
    assert blk.shape == (16, 16, 3) and blk.dtype == np.uint8
    assert (blk == one[32:48, 64:80]).all()
    # or as an image (it was a .npy array written under the name b.png, which no viewer opens)
    assert main(["decode", str(encoded), "--block", "3,5,2,4", "--out", str(tmp_path / "b.png"), "--quiet"]) == 0
    assert (read_image(tmp_path / "b.png") == blk).all()
    assert main(["decode", str(encoded), "--block", "3,5,2,4", "--out", str(tmp_path / "b.jpg"), "--quiet"]) == 2
    assert "--block --out writes .png, .tif, .tiff, .npy" in capsys.readouterr().err
    assert not (tmp_path / "b.jpg").exists()
    # the last block: 160 px wide = 10 blocks, 128 high = 8 blocks (exact), at level 1 too
    assert main(["decode", str(encoded), "--block", "3,5,7,9", "--out", str(tmp_path / "e.npy"), "--level", "1",
                 "--quiet"]) == 0
    assert np.load(tmp_path / "e.npy").shape == (16, 16, 3)
    # --view ROW,COL --out FILE: one view to one file, an image or an array
    assert main(["decode", str(encoded), "--view", "3,5", "--out", str(tmp_path / "v.png"), "--quiet"]) == 0
    assert (read_image(tmp_path / "v.png") == one).all()
    assert main(["decode", str(encoded), "--view", "3,5", "--out", str(tmp_path / "v.npy")]) == 0
    assert "wrote" in capsys.readouterr().out and (np.load(tmp_path / "v.npy") == one).all()
    assert main(["decode", str(encoded), "--view", "3,5", "--out", str(tmp_path / "v.tif"), "--quiet"]) == 0
    assert (read_image(tmp_path / "v.tif") == one).all()
    # a file name given where the folder goes, with --view or --block, is that one file (it made a
    # folder named p.png holding r03_c05.png); an existing folder of such a name stays a folder
    assert main(["decode", str(encoded), str(tmp_path / "p.png"), "--view", "3,5", "--quiet"]) == 0
    assert (tmp_path / "p.png").is_file() and (read_image(tmp_path / "p.png") == one).all()
    assert main(["decode", str(encoded), str(tmp_path / "pb.npy"), "--block", "3,5,2,4", "--quiet"]) == 0
    assert (np.load(tmp_path / "pb.npy") == blk).all()
    assert main(["decode", str(encoded), str(tmp_path / "p.jpg"), "--view", "3,5", "--quiet"]) == 2
    assert ".png, .tif, .tiff, .npy" in capsys.readouterr().err and not (tmp_path / "p.jpg").exists()
    (tmp_path / "dir.png").mkdir()
    assert main(["decode", str(encoded), str(tmp_path / "dir.png"), "--view", "3,5", "--quiet"]) == 0
    assert (read_image(tmp_path / "dir.png" / "r03_c05.png") == one).all()
    for lossy in ("v.jpg", "v.xyz", "v"):      # a JPEG would drop bit depth and channels without a word
        assert main(["decode", str(encoded), "--view", "3,5", "--out", str(tmp_path / lossy), "--quiet"]) == 2
        assert ".png, .tif, .tiff, .npy" in capsys.readouterr().err and not (tmp_path / lossy).exists()


@pytest.mark.parametrize("args", [["--block", "0,0,0,0", "--out", "{in}"], ["--view", "0,0", "--out", "{in}"],
                                  ["--view", "0,0", "--out", "{link}"], ["--out", "{tmp}/x.png"],
                                  ["{tmp}/d", "--view", "0,0", "--out", "{tmp}/x.png"]])
def test_decode_refuses_outputs_that_are_the_input(encoded, tmp_path, args, capsys):
    # the input .lfc written over by a decode (it was: --block ... --out IN.lfc replaced it)
    f = tmp_path / "in.lfc"
    f.write_bytes(encoded.read_bytes())
    (tmp_path / "link.lfc").symlink_to(f)
    before = f.read_bytes()
    args = [x.format(**{"in": str(f), "link": str(tmp_path / "link.lfc"), "tmp": str(tmp_path)}) for x in args]
    assert main(["decode", str(f), *args, "--quiet"]) == 2
    assert f.read_bytes() == before and not (tmp_path / "x.png").exists()
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and ("input file" in err or "--out" in err)


def test_decode_into_a_folder_replaces_only_its_own_views(encoded, tmp_path, capsys):
    # decoding into a capture's own folder (--names original, or a grid named as decoded views)
    # replaced the user's images with lossy ones; now only files that already hold the decoded
    # views are left in place (a decode run again), anything else stops it unless --overwrite
    from formats.imageio import write_image

    out = tmp_path / "v"
    assert main(["decode", str(encoded), str(out), "--quiet"]) == 0
    when = {p.name: p.stat().st_mtime_ns for p in out.iterdir()}
    assert main(["decode", str(encoded), str(out), "--quiet"]) == 0                    # again: nothing rewritten
    assert all(p.stat().st_mtime_ns == when[p.name] for p in out.iterdir() if p.suffix == ".png")
    mine = read_image(out / "r03_c05.png")
    theirs = np.ascontiguousarray(mine[::-1])                                          # a user's own image there
    write_image(out / "r03_c05.png", theirs)
    (out / "r00_c00.png").unlink()
    for args in ([], ["--view", "3,5"]):
        assert main(["decode", str(encoded), str(out), *args, "--quiet"]) == 2
        assert "r03_c05.png: exists" in capsys.readouterr().err
        assert (read_image(out / "r03_c05.png") == theirs).all() and not (out / "r00_c00.png").exists()
    assert main(["decode", str(encoded), str(out), "--overwrite", "--quiet"]) == 0
    assert (read_image(out / "r03_c05.png") == mine).all() and (out / "r00_c00.png").exists()
    # a layout file lfcodec did not write is the capture's own, too
    own = tmp_path / "own"
    own.mkdir()
    (own / "scene.json").write_text('{"layout": "grid", "rows": 9, "cols": 9}')
    assert main(["decode", str(encoded), str(own), "--quiet"]) == 2
    assert (own / "scene.json").read_text() == '{"layout": "grid", "rows": 9, "cols": 9}'
    assert [p.name for p in own.iterdir()] == ["scene.json"]


def test_encode_refuses_an_image_name_for_its_container(tmp_path, capsys):
    """``lfcodec encode SCENE out.png`` wrote an .lfc container under an image's name (over an
    image of that name too); now one line, exit 2, and nothing written."""
    from formats.imageio import write_image

    photo = tmp_path / "photo.png"
    write_image(photo, np.zeros((4, 4, 3), np.uint8))
    before = photo.read_bytes()
    for name in ("photo.png", "x.JPG", "x.npy", "x.tif"):
        assert main(["encode", str(SAMPLE), str(tmp_path / name), "--quiet"]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and ".lfc container" in err and "lfcodec decode" in err
    assert photo.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == ["photo.png"]


def test_render_refuses_to_write_over_its_input(encoded, tmp_path):
    f = tmp_path / "in.png"                      # (an .lfc file however it is named)
    f.write_bytes(encoded.read_bytes())
    before = f.read_bytes()
    assert main(["render", str(f), str(f), "--quiet"]) == 2
    assert f.read_bytes() == before


def test_render_alone_asks_malloc_to_keep_freed_blocks(encoded, tmp_path, monkeypatch):
    """``lfcodec render`` (frame after frame) asks for formats.heap.keep_freed; decode and encode
    do not (a one-pass decode gains nothing and peaks higher; the encoder has a memory line)."""
    import formats.heap as heap

    calls = []
    monkeypatch.setattr(heap, "keep_freed", lambda *a: calls.append(a) or True)
    assert main(["render", str(encoded), str(tmp_path / "r.png"), "--quiet"]) == 0 and len(calls) >= 1
    n = len(calls)                   # (the command asks, and so does the library's renderer)
    assert main(["decode", str(encoded), "--view", "0,0", "--out", str(tmp_path / "v.png"), "--quiet"]) == 0
    assert len(calls) == n


@pytest.mark.parametrize("profile,top,view", [("auto", 1, "1,1"), ("bise", 3, "0,0"), ("dcp", 1, "0,0")])
def test_progressive_decode_levels(profile, top, view, tmp_path):
    enc = tmp_path / "p.lfc"
    assert main(["encode", str(SAMPLE), str(enc), "--profile", profile, "--quant", "3", "--quiet"]) == 0
    for L in (0, top):
        assert main(["decode", str(enc), str(tmp_path / f"L{L}"), "--view", view, "--level", str(L), "--quiet"]) == 0
    name = "r%02d_c%02d.png" % tuple(map(int, view.split(",")))
    a, b = read_image(tmp_path / "L0" / name), read_image(tmp_path / f"L{top}" / name)
    assert a.shape == b.shape and not (a == b).all()
    assert main(["decode", str(enc), str(tmp_path / "bad"), "--level", str(top + 1), "--quiet"]) == 2


def test_decode_that_fails_part_way_leaves_no_views(encoded, tmp_path, monkeypatch, capsys):
    """Views are decoded and written a row at a time; a file that fails at a later row (a
    damaged stream) leaves none of its views in the folder, and says why in one line."""
    from formats.errors import ChecksumError
    from rlfc.decoder import RlfcDecoder

    calls = []
    real = RlfcDecoder.decode_views

    def fail_third_row(self, views=None, *a, **k):
        calls.append(1)
        if len(calls) == 3:
            raise ChecksumError("dino.lfc: section 'tx.blocks' is corrupt (test)")
        return real(self, views, *a, **k)

    monkeypatch.setattr(RlfcDecoder, "decode_views", fail_third_row)
    out = tmp_path / "part"
    assert main(["decode", str(encoded), str(out), "--quiet"]) == 2
    assert "corrupt" in capsys.readouterr().err and len(calls) == 3
    assert not any(out.iterdir())


def test_decode_whose_file_write_fails_leaves_no_views(encoded, tmp_path, failing_write, capsys):
    """Files are written on threads while the next row decodes; a write that fails (here the
    second row's second view) stops the decode with its one-line error, and no views stay."""
    import formats.scenes as scenes

    failing_write(scenes, "r01_c01.png", "No space left on device")
    out = tmp_path / "full"
    assert main(["decode", str(encoded), str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "No space left" in err[0]
    assert not out.exists() or not any(out.iterdir())


def _run(*args):
    r = subprocess.run([sys.executable, "-m", "formats.cli", *args], capture_output=True, text=True, cwd=ROOT)
    return r.returncode, r.stdout, r.stderr


@pytest.mark.parametrize("args,needle", [
    (["info", "nope.lfc"], "cannot open"),
    (["info", "README.md"], "magic"),
    (["encode", "nope_dir", "x.lfc"], "no such scene"),
    (["encode", "rlfc", "x.lfc"], "no recognizable"),
    (["decode", "nope.lfc", "out"], "cannot open"),
    (["encode", str(SAMPLE), "x.lfc", "--block-size", "5"], "block size"),
    (["encode", str(SAMPLE), str(SAMPLE / "scene.json")], "refusing"),
    (["encode", str(SAMPLE), "x.lfc", "--workers", "0"], "--workers"),
    (["encode", str(SAMPLE), "x.lfc", "--scheduler", "nowhere"], "address"),
    (["encode", str(SAMPLE), "x.lfc", "--workers", "2", "--scheduler", "tcp://127.0.0.1:1"], "not both"),
    (["encode", str(SAMPLE), "x.lfc", "--min-view-psnr", "nan"], "floor"),
    (["encode", str(SAMPLE), "x.lfc", "--min-view-psnr", "1e11"], "floor"),
    (["view", "nope.lfc"], "no such file"),
    (["view", "README.md", "--port", "70000"], "--port"),
    (["encode", str(SAMPLE), "x.lfc", "--grid", "100000x2"], "1..99999"),
])
def test_bad_input_one_line_exit_2(args, needle):
    code, out, err = _run(*args)
    assert code == 2, (code, err)
    assert err.strip().count("\n") == 0 and needle in err and "Traceback" not in err


def test_float_image_folder_is_one_line_exit_2(tmp_path):
    """A folder of float TIFFs (HDR) reads as float32 views: no codec here codes them, and the
    command says so in one line instead of a numpy traceback."""
    import cv2

    for i in range(4):
        cv2.imwrite(str(tmp_path / f"v{i}.tif"), np.full((12, 16, 3), 0.25 * i, np.float32))
    for codec in ("rlfc", "lfn"):
        code, out, err = _run("encode", str(tmp_path), str(tmp_path / "x.lfc"), "--grid", "2x2", "--codec", codec,
                              "--quiet")
        assert code == 2 and err.strip().count("\n") == 0 and "Traceback" not in err, (codec, err)
        assert "16-bit" in err


def test_bad_block_and_level_requests(encoded):
    for args, needle in ((["--block", "9,0,0,0"], "outside"), (["--block", "0,0,99,0"], "outside"),
                         (["--block", "1,2,3"], "4 non-negative"), (["--block", "0,0,0,0", "--level", "9"], "level")):
        code, out, err = _run("decode", str(encoded), *args, "--out", "/tmp/never.npy")
        assert code == 2 and needle in err and err.strip().count("\n") == 0, err


def test_corrupt_and_truncated_files(encoded, tmp_path):
    blob = bytearray(encoded.read_bytes())
    (tmp_path / "trunc.lfc").write_bytes(bytes(blob[:-1000]))
    from formats.container import Container
    last = list(Container(bytes(blob)).sections)[-1]
    code, _, err = _run("info", str(tmp_path / "trunc.lfc"))
    assert code == 2 and "truncated" in err and last in err
    info = Container(bytes(blob)).info(last)
    blob[info.offset + 100] ^= 0xFF
    (tmp_path / "flip.lfc").write_bytes(bytes(blob))
    code, _, err = _run("info", str(tmp_path / "flip.lfc"), "--verify")
    assert code == 2 and last in err and "checksum" in err
    code, _, err = _run("decode", str(tmp_path / "flip.lfc"), str(tmp_path / "o"), "--quiet")
    assert code == 2 and last in err


def test_help_for_each_command():
    for cmd in ("info", "encode", "decode"):
        code, out, _ = _run(cmd, "--help")
        assert code == 0 and "usage" in out


@pytest.fixture(scope="module")
def grey16_scene(tmp_path_factory):
    """The sample as a 16-bit greyscale grid in HCI naming (a layout and depth users have)."""
    from formats.imageio import write_image

    out = tmp_path_factory.mktemp("g16")
    lf = read_scene(SAMPLE)
    for r in range(9):
        for c in range(9):
            g = lf.views[r, c].astype(np.float64) @ [0.299, 0.587, 0.114]
            write_image(out / f"input_Cam{r * 9 + c:03d}.png", np.round(g * 257).astype(np.uint16))
    return out


def test_16bit_grey_works_like_rgb(grey16_scene, tmp_path, capsys):
    out = tmp_path / "g.lfc"
    assert main(["encode", str(grey16_scene), str(out), "--json", "--quiet"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["channels"] == 1 and rep["dtype"] == "uint16"
    assert 36 < rep["psnr_rgb"] < 48 and rep["bpp"] < 3        # default step scales with the depth
    assert main(["encode", str(grey16_scene), str(out), "--target-psnr", "40"]) == 0
    line = capsys.readouterr().out                      # the grey channel's PSNR, not called RGB
    assert ", PSNR (grey) 40." in line and "RGB" not in line
    assert main(["encode", str(grey16_scene), str(out), "--target-psnr", "40", "--json", "--quiet"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert 40 <= rep["psnr_rgb"] < 40.6
    assert main(["decode", str(out), str(tmp_path / "v"), "--view", "8,8", "--quiet"]) == 0
    img = read_image(tmp_path / "v" / "r08_c08.png")
    assert img.shape == (128, 160, 1) and img.dtype == np.uint16
    assert main(["decode", str(out), "--block", "8,8,7,9", "--out", str(tmp_path / "b.npy"), "--quiet"]) == 0
    blk = np.load(tmp_path / "b.npy")
    assert blk.dtype == np.uint16 and (blk == img[112:128, 144:160]).all()
    assert main(["encode", str(grey16_scene), str(out), "--lossless", "--quiet"]) == 0
    from formats.registry import open_decoder
    from formats.lfcfile import open_lfc
    with open_lfc(out) as f:
        assert (open_decoder(f).decode_all() == read_scene(grey16_scene).views).all()


def test_dcp_profile_from_the_cli(tmp_path, capsys):
    out = tmp_path / "dcp.lfc"
    assert main(["encode", str(SAMPLE), str(out), "--profile", "dcp", "--target-psnr", "40", "--json", "--quiet",
                 "--workers", "2"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["profile"] == "dcp" and rep["psnr_rgb"] >= 40
    assert any("--workers/--scheduler had no effect" in n for n in rep["notes"])     # dcp codes in one process
    assert 39 <= rep["params"]["top_psnr"] <= 46          # key-view quality is searched too
    assert rep["bpp"] < 0.15                               # bise needs 1.73 bpp for 40 dB on the sample
    assert main(["info", str(out), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["decoder"]["profile"] == "dcp" and "rlfc.disp" in [s["name"] for s in info["sections"]]
    assert main(["decode", str(out), "--block", "4,4,2,3", "--out", str(tmp_path / "b.npy"), "--quiet"]) == 0
    assert main(["decode", str(out), str(tmp_path / "v"), "--view", "4,4", "--quiet"]) == 0
    assert (np.load(tmp_path / "b.npy") == read_image(tmp_path / "v" / "r04_c04.png")[16:24, 24:32]).all()


def test_posed_captures_code_view_by_view_and_round_trip(tmp_path, capsys):
    """--profile auto (the default) codes a posed capture with tx, every view on its own (the
    report says so); dcp refuses it; decode writes a transforms.json with the poses, and the
    decoded folder encodes again to the same views and cameras."""
    from formats.imageio import write_image

    scene = tmp_path / "posed"
    (scene / "train").mkdir(parents=True)
    rng = np.random.default_rng(0)
    frames = []
    for i in range(3):
        write_image(scene / "train" / f"r_{i}.png", rng.integers(0, 256, (16, 24, 3), dtype=np.uint8))
        m = np.eye(4)
        m[0, 3] = 0.1 * i
        frames.append({"file_path": f"./train/r_{i}", "transform_matrix": m.tolist()})
    (scene / "transforms_train.json").write_text(json.dumps({"camera_angle_x": 0.5, "frames": frames}))
    (scene / "transforms_test.json").write_text(json.dumps({"camera_angle_x": 0.5, "frames": frames[:1]}))
    assert main(["encode", str(scene), str(tmp_path / "p.lfc"), "--lossless", "--json", "--quiet"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["profile"] == "tx" and any("coded on its own" in w for w in rep["notes"])
    assert any("split 'test'" in w and "--split test" in w for w in rep["notes"])     # not dropped silently
    (scene / "transforms_test.json").unlink()
    assert main(["encode", str(scene), str(tmp_path / "q.lfc"), "--profile", "dcp", "--quiet"]) == 2
    assert main(["decode", str(tmp_path / "p.lfc"), str(tmp_path / "dec"), "--quiet"]) == 0
    assert (tmp_path / "dec" / "transforms.json").is_file()
    a, b = read_scene(scene), read_scene(tmp_path / "dec")
    assert (a.views == b.views).all() and np.allclose(a.c2w, b.c2w) and np.allclose(a.focal, b.focal)
    assert b.layout == "posed"


def test_decoded_grid_folder_encodes_again(encoded, tmp_path):
    assert main(["decode", str(encoded), str(tmp_path / "dec"), "--quiet"]) == 0
    cfg = json.loads((tmp_path / "dec" / "scene.json").read_text())
    assert cfg["layout"] == "grid" and cfg["views"] == "r{row:02d}_c{col:02d}.png"
    a, b = read_scene(SAMPLE), read_scene(tmp_path / "dec")
    assert a.views.shape == b.views.shape and np.allclose(a.positions, b.positions) and a.focal == b.focal


@pytest.mark.parametrize("profile", ["dcp", "tx"])
def test_target_bpp_per_profile(profile, tmp_path, capsys):
    out = tmp_path / "b.lfc"
    assert main(["encode", str(SAMPLE), str(out), "--profile", profile, "--target-bpp", "0.1", "--json",
                 "--quiet"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["profile"] == profile and 0.05 < rep["bpp"] <= 0.1 and rep["psnr_rgb"] > 38 and rep["target_met"]


def test_plain_folder_with_grid_option(tmp_path, capsys):
    from formats.imageio import write_image

    folder = tmp_path / "imgs"
    folder.mkdir()
    rng = np.random.default_rng(1)
    views = rng.integers(0, 256, (2, 3, 16, 16, 3), dtype=np.uint8)
    for i in range(6):                                   # img2 sorts before img10 (natural order)
        write_image(folder / f"img{[1, 2, 3, 10, 11, 12][i]}.png", views.reshape(6, 16, 16, 3)[i])
    assert main(["encode", str(folder), str(tmp_path / "a.lfc"), "--quiet"]) == 2
    assert "--grid" in capsys.readouterr().err
    assert main(["encode", str(folder), str(tmp_path / "a.lfc"), "--grid", "3x3", "--quiet"]) == 2
    assert main(["encode", str(folder), str(tmp_path / "a.lfc"), "--grid", "2x", "--quiet"]) == 2
    assert main(["encode", str(folder), str(tmp_path / "a.lfc"), "--grid", "2x3", "--lossless", "--quiet"]) == 0
    assert main(["decode", str(tmp_path / "a.lfc"), str(tmp_path / "d"), "--quiet"]) == 0
    assert (read_scene(tmp_path / "d").views == views).all()


def test_corrupt_image_is_one_line_and_decode_needs_the_parent_folder(tmp_path, capfd):
    """libpng's own "libpng error: ..." line is held back (the SceneError names the file and the
    error); decode, like encode, makes no folders on the way to its output."""
    import shutil

    scene = tmp_path / "scene"
    shutil.copytree(SAMPLE, scene)
    png = scene / "views" / "r03_c04.png"
    png.write_bytes(png.read_bytes()[:3000])
    capfd.readouterr()
    assert main(["encode", str(scene), str(tmp_path / "x.lfc"), "--quiet"]) == 2
    err = capfd.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "r03_c04.png" in err[0] and "libpng" not in err[0], err
    golden = ROOT / "tests" / "data" / "golden" / "rlfc_tx2_lossy_rgb8.lfc"
    assert main(["decode", str(golden), str(tmp_path / "no" / "such" / "out"), "--quiet"]) == 2
    assert "does not exist" in capfd.readouterr().err and not (tmp_path / "no").exists()
    assert main(["decode", str(golden), str(tmp_path / "out"), "--quiet"]) == 0     # the folder itself is made
    assert (tmp_path / "out" / "r00_c00.png").is_file()


def test_split_all_encodes_every_split_and_decodes_them_back(tmp_path, capsys):
    """--split all: a NeRF-style folder's splits as one posed capture; decode --names original
    writes each split back to its own transforms_<split>.json and folder, which reads again (split
    all) to the same views, cameras and split sizes."""
    from formats.imageio import write_image

    scene = tmp_path / "posed"
    rng = np.random.default_rng(1)
    for split, n in (("train", 3), ("test", 2)):
        (scene / split).mkdir(parents=True)
        frames = []
        for i in range(n):
            write_image(scene / split / f"r_{i}.png", rng.integers(0, 256, (16, 24, 3), dtype=np.uint8))
            m = np.eye(4)
            m[:3, 3] = [0.1 * i, 0.05 * len(split), 0.0]
            frames.append({"file_path": f"./{split}/r_{i}", "transform_matrix": m.tolist()})
        (scene / f"transforms_{split}.json").write_text(json.dumps({"camera_angle_x": 0.5, "frames": frames}))
    a = read_scene(scene, split="all")
    assert a.cols == 5 and a.meta["splits"] == [("train", 3), ("test", 2)]
    assert main(["encode", str(scene), str(tmp_path / "p.lfc"), "--split", "all", "--lossless", "--json",
                 "--quiet"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["views"] == 5 and not any("was not encoded" in n for n in rep["notes"])
    assert main(["decode", str(tmp_path / "p.lfc"), str(tmp_path / "dec"), "--names", "original", "--quiet"]) == 0
    assert sorted(p.name for p in (tmp_path / "dec").glob("transforms*.json")) == ["transforms_test.json",
                                                                                  "transforms_train.json"]
    assert (tmp_path / "dec" / "test" / "r_1.png").is_file()
    b = read_scene(tmp_path / "dec", split="all")
    assert (a.views == b.views).all() and np.allclose(a.c2w, b.c2w) and b.meta["splits"] == a.meta["splits"]
    assert read_scene(tmp_path / "dec", split="test").cols == 2
    assert main(["encode", str(scene), str(tmp_path / "v.lfc"), "--split", "val", "--quiet"]) == 2
    assert "no transforms_val.json (the splits here: test, train" in capsys.readouterr().err
    # intrinsics that differ between splits are refused, not mixed
    doc = json.loads((scene / "transforms_test.json").read_text())
    (scene / "transforms_test.json").write_text(json.dumps({**doc, "camera_angle_x": 0.7}))
    assert main(["encode", str(scene), str(tmp_path / "q.lfc"), "--split", "all", "--quiet"]) == 2
    assert "intrinsics" in capsys.readouterr().err


def test_outputs_that_are_folders_or_fifos(encoded, tmp_path, capsys):
    # an output named like a file that is a folder: one line naming it (the message named a temp
    # file, and a failed image write left its temp file behind); an input that is a FIFO or a
    # device: refused before the open (a FIFO blocked the open)
    import os

    for name in ("b.npy", "v.png", "r.png", "e.lfc", "m.mp4"):
        (tmp_path / name).mkdir()
    for argv in (["decode", str(encoded), "--block", "0,0,0,0", "--out", str(tmp_path / "b.npy")],
                 ["decode", str(encoded), "--view", "0,0", "--out", str(tmp_path / "v.png")],
                 ["render", str(encoded), str(tmp_path / "r.png")],
                 ["encode", str(SAMPLE), str(tmp_path / "e.lfc"), "--quant", "8"],
                 ["render", str(encoded), str(tmp_path / "m.mp4"), "--path", "orbit:2"]):
        assert main(argv + ["--quiet"]) == 2
        err = capsys.readouterr().err
        assert "is a folder" in err and err.count("\n") == 1, argv
    assert sorted(p.name for p in tmp_path.iterdir()) == ["b.npy", "e.lfc", "m.mp4", "r.png", "v.png"]   # no temps
    os.mkfifo(tmp_path / "f.lfc")
    for src in (str(tmp_path / "f.lfc"), "/dev/null", str(tmp_path)):
        assert main(["info", src]) == 2
        assert "not a regular file" in capsys.readouterr().err


def test_failed_image_writes_leave_no_temp_file(tmp_path):
    from formats.errors import SceneError
    from formats.imageio import write_image

    (tmp_path / "x.png").mkdir()
    with pytest.raises(SceneError, match="cannot write"):
        write_image(tmp_path / "x.png", np.zeros((4, 4, 3), np.uint8))
    assert [p.name for p in tmp_path.iterdir()] == ["x.png"]


def test_scene_options_the_reader_did_not_use_are_reported(tmp_path, capsys):
    # --grid on a folder with its own scene.json, --split on a grid: they passed in silence
    out = tmp_path / "o.lfc"
    assert main(["encode", str(SAMPLE), str(out), "--grid", "3x27", "--split", "test", "--quant", "8", "--json",
                 "--quiet"]) == 0
    notes = json.loads(capsys.readouterr().out)["notes"]
    assert any("--grid 3x27 was not used" in n for n in notes) and any("--split test was not used" in n for n in notes)
    assert main(["encode", str(SAMPLE), str(out), "--baseline", "2", "--quant", "8", "--json", "--quiet"]) == 0
    assert not any("not used" in n for n in json.loads(capsys.readouterr().out)["notes"])   # a grid's baseline is used


def test_outputs_under_a_file_name_the_file(encoded, tmp_path, capsys):
    """An output path whose folder is a file: one line saying so, before any work (encode named
    its temp file with 'Not a directory', render --path gave the bare OS error)."""
    f = tmp_path / "in.lfc"
    f.write_bytes(encoded.read_bytes())
    for argv in (["encode", str(SAMPLE), f"{f}/x.lfc"], ["decode", str(f), f"{f}/sub"],
                 ["decode", str(f), "--view", "0,0", "--out", f"{f}/v.png"], ["render", str(f), f"{f}/x.png"],
                 ["render", str(f), f"{f}/seq", "--path", "orbit:2"]):
        assert main(argv + ["--quiet"]) == 2, argv
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "is a file, not a folder" in err, (argv, err)
