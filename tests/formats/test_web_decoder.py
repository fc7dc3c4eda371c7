"""The browser viewer's JavaScript decoder (formats/web/lfc.js), run under Node: the same planes
as the Python decoder, bit for bit, on golden files (grey+alpha 16-bit lossless, RGB, RGBA) and
on files encoded from a real capture (the bundled Lytro crop, with and without JPEG 2000 key
views); its renderer within rounding of the Python renderer; typed errors on bad files.

Skipped with the reason where Node.js is not installed (CI installs it)."""
from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from formats import open_decoder, open_lfc
from formats.metrics import psnr_rgb
from tests.formats.frames import assert_same_frame

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
GOLDEN = ROOT / "tests" / "data" / "golden"
NODE = shutil.which("node")
pytestmark = pytest.mark.skipif(NODE is None, reason="Node.js is not installed (apt-get install nodejs)")


def run_js(path: Path, out: Path, cams=(), chunk_budget=None) -> dict:
    import os

    env = dict(os.environ, LFC_CHUNK_BUDGET=str(chunk_budget)) if chunk_budget is not None else None
    got = subprocess.run([NODE, str(ROOT / "tools" / "web_decode.mjs"), str(path), str(out), *cams], capture_output=True,
                         text=True, timeout=600, env=env)
    assert got.returncode == 0, got.stderr[-3000:]
    return json.loads(got.stdout.strip().splitlines()[-1])


def js_planes(out: Path, info: dict, v: int, h: int, w: int) -> np.ndarray:
    a = np.fromfile(out / f"view_{v}.bin", np.int32).reshape(info["Hp"], info["Wp"], info["P"])
    return a[:h, :w]


def assert_same_planes(path: Path, out: Path, exact: bool = True, chunk_budget=None) -> int:
    info = run_js(path, out, chunk_budget=chunk_budget)
    assert info["ok"], info
    d = open_decoder(open_lfc(path))
    py = d.decode_views(planes=True)
    differ = 0
    for v in range(info["n"]):
        js = js_planes(out, info, v, d.height, d.width)
        if exact:
            np.testing.assert_array_equal(js, py[v], err_msg=f"{path.name} view {v}")
        else:
            assert np.abs(js - py[v]).max() <= 1
            differ += int((js != py[v]).sum())
    return differ


@pytest.mark.parametrize("name", ["rlfc_tx2_lossless_ga16", "rlfc_tx2_lossy_rgb8", "rlfc_tx2_lossy_rgba8",
                                  "rlfc_tx3_lossy_rgb8", "rlfc_txsplit_lossy_rgb8", "rlfc_tx4_weighted_rgb8",
                                  "rlfc_tx5_warped_rgb8", "rlfc_tx6_alpha_rgba8", "rlfc_tx6_alpha_ga16"])
def test_golden_files_bit_exact(name, tmp_path):
    assert_same_planes(GOLDEN / f"{name}.lfc", tmp_path)


@pytest.fixture(scope="module")
def sample_files(tmp_path_factory):
    """The bundled Lytro crop encoded twice: transform-coded key views with residual
    blocks (a small quantizer step forces coded blocks), and a JPEG 2000 intra key view."""
    from formats.cli import main

    d = tmp_path_factory.mktemp("web")
    tx, j2k = d / "tx.lfc", d / "j2k.lfc"
    assert main(["encode", str(ROOT / "samples" / "dino_crop"), str(tx), "--quant", "3", "--intra-codec", "tx",
                 "--quiet"]) == 0
    assert main(["encode", str(ROOT / "samples" / "dino_crop"), str(j2k), "--target-psnr", "36", "--intra-codec",
                 "j2k", "--quiet"]) == 0
    return tx, j2k


def test_key_views_are_decoded_on_demand(sample_files, tmp_path):
    """An open decodes no key view; the first view decodes only the keys it is predicted from
    (and theirs), not all of them; every view is still the Python decoder's (the test below)."""
    tx, _ = sample_files
    info = run_js(tx, tmp_path, ())
    assert info["ok"] and info["keys"] > 2, info
    assert info["keys_at_open"] == 0 and 0 < info["keys_after_first"] < info["keys"], info


def test_real_capture_with_residual_blocks_bit_exact(sample_files, tmp_path):
    tx, _ = sample_files
    d = open_decoder(open_lfc(tx))
    assert d.core.coded.sum() > 0                    # the residual path is exercised
    assert_same_planes(tx, tmp_path)
    assert_same_planes(tx, tmp_path / "small", chunk_budget=1)   # every chunk dropped after use, fetched again


def test_key_rows_in_several_streams_bit_exact(tmp_path):
    """tx layout version 3: each key-view block row coded as key_split streams."""
    from formats.cli import main

    f = tmp_path / "split.lfc"
    assert main(["encode", str(ROOT / "samples" / "dino_crop"), str(f), "--quant", "3", "--intra-codec", "tx",
                 "--key-split", "4", "--quiet"]) == 0
    d = open_decoder(open_lfc(f))
    assert d.core.key_split > 1 and d.core.coded.sum() > 0
    assert_same_planes(f, tmp_path / "out")


def test_jpeg2000_key_views_agree(sample_files, tmp_path):
    """JPEG 2000's 9/7 inverse is floating point (the standard bounds its error, not its bits):
    OpenJPEG/wasm and imagecodecs' OpenJPEG may differ by 1 at a few samples."""
    _, j2k = sample_files
    d = open_decoder(open_lfc(j2k))
    assert d.core.img_of                              # the file has a JPEG 2000 key view
    differ = assert_same_planes(j2k, tmp_path, exact=False)
    assert differ <= 0.001 * d.rows * d.cols * d.height * d.width * d.P


def test_renderer_matches_python(sample_files, tmp_path):
    tx, _ = sample_files
    cams = ["4,4,nan,0", "3.25,5.6,nan,0", "2.6,1.3,nan,0", "4,4,1.5,2", "2.3,1.7,0.5,0", "0,8,nan,0"]
    info = run_js(tx, tmp_path, cams)
    assert info["ok"], info
    d = open_decoder(open_lfc(tx))
    r = d.renderer()                                  # robust, the default of both
    for i, c in enumerate(cams):
        s, t, focus, ap = (float(x) for x in c.split(","))
        py = r.render(s, t, None if np.isnan(focus) else focus, ap)
        js = np.fromfile(tmp_path / f"render_{i}.bin", py.dtype).reshape(py.shape)
        if c == "4,4,nan,0":                          # a captured view: exactly its pixels
            np.testing.assert_array_equal(js, d.decode_view(4, 4))
        assert_same_frame(py, js)


@pytest.mark.parametrize("name", ["rlfc_tx2_lossless_ga16.lfc", "rlfc_tx6_alpha_rgba8.lfc"])
def test_renderer_matches_python_on_grey_alpha_and_16_bit(name, tmp_path):
    """Grey+alpha 16-bit and RGBA golden files (29×37 views: padding blocks past the frame):
    the JavaScript frames are the Python ones within rounding. Before stop 84 they were 29–32 dB
    apart (16-bit: up to 15 082 levels): the Python robust choice took its median over the
    padding's blocks too, and OpenCV 5.0 rounds two-channel bilinear positions to 1/32 px."""
    f = GOLDEN / name
    cams = ["0.9,1.8,nan,0", "1.65,1.2,nan,0", "3,1.5,nan,0", "2.3,0.4,0.7,0", "1.5,1.5,0.5,1.2"]
    info = run_js(f, tmp_path, cams)
    assert info["ok"], info
    d = open_decoder(open_lfc(f))
    r = d.renderer()
    for i, c in enumerate(cams):
        s, t, focus, ap = (float(x) for x in c.split(","))
        py = r.render(s, t, None if np.isnan(focus) else focus, ap)
        js = np.fromfile(tmp_path / f"render_{i}.bin", py.dtype).reshape(py.shape)
        assert_same_frame(py, js, share=0.002)


def test_renderer_applies_per_view_warps_like_python(tmp_path):
    """tx version 5 (the golden file's warps): both renderers move each source's samples by its
    warp less the camera's (the sources' blend of theirs): a captured view is its own pixels, and
    in between the JavaScript frame is the Python one within rounding, not the frame without warps."""
    f = GOLDEN / "rlfc_tx5_warped_rgb8.lfc"
    cams = ["1,2,nan,0", "1.5,2.25,nan,0", "0.4,0.7,nan,0", "2.5,1.5,0.5,1.5", "1.7,2.8,nan,0"]
    info = run_js(f, tmp_path, cams)
    assert info["ok"], info
    d = open_decoder(open_lfc(f))
    r = d.renderer()
    plain = d.renderer()
    plain._warp = None                                # (the same file, its warps ignored)
    apart = 0.0
    for i, c in enumerate(cams):
        s, t, focus, ap = (float(x) for x in c.split(","))
        focus = None if np.isnan(focus) else focus
        py = r.render(s, t, focus, ap)
        js = np.fromfile(tmp_path / f"render_{i}.bin", py.dtype).reshape(py.shape)
        if c == "1,2,nan,0":
            np.testing.assert_array_equal(js, d.decode_view(1, 2))
            continue
        assert_same_frame(py, js)
        apart = max(apart, psnr_rgb(py, js) - psnr_rgb(plain.render(s, t, focus, ap), js))
    assert apart > 3.0                               # the warps change the frames


def _kernel_tool(tool: str, name: str, sample_files, tmp_path) -> dict:
    """tools/TOOL's JSON line (with 0 timed rounds) on a file: "grey" (a 3×3 grey grid made here),
    "sample" (the bundled crop) or a golden file's name."""
    from tests.rlfc.helpers import open_encoded, smooth_lf
    from tests.rlfc.test_tx import tx

    if name == "grey":
        lf = smooth_lf(rows=3, cols=3, h=24, w=32, c=1)
        _, blob = open_encoded(lf, tx(lf, step=6.0))
        path = tmp_path / "grey.lfc"
        path.write_bytes(blob)
    else:
        path = sample_files[0] if name == "sample" else GOLDEN / name
    got = subprocess.run([NODE, str(ROOT / "tools" / tool), str(path), "0"], capture_output=True, text=True, timeout=300)
    assert got.returncode == 0, got.stderr[-3000:]
    info = json.loads(got.stdout.strip().splitlines()[-1])
    assert info["kernel"], "this Node has no WebAssembly SIMD"
    assert info["P"] == {"grey": 1, "rlfc_tx2_lossless_ga16.lfc": 2, "rlfc_tx6_alpha_rgba8.lfc": 4}.get(name, 3)
    assert info["warps"] == (name == "rlfc_tx5_warped_rgb8.lfc")
    return info


@pytest.mark.parametrize("name", ["rlfc_tx2_lossless_ga16.lfc", "rlfc_tx5_warped_rgb8.lfc", "rlfc_tx6_alpha_rgba8.lfc",
                                  "grey", "sample"])
def test_blend_kernel_matches_the_loops_bit_for_bit(name, sample_files, tmp_path):
    """The novel-view blend on WebAssembly SIMD (render_kernel.wat: two planes at a time, an odd
    plane alone) makes blendOne's float32 accumulator bit for bit: 1 (grey), 2 (grey+alpha,
    16-bit), 3 (with per-view warps; the Lytro crop) and 4 (RGBA) planes; bicubic and bilinear;
    the maps, a focus, a synthetic aperture; a band of rows as the workers blend; whole robust
    frames; the robust choice's costs (its samples on render_kernel.wat's `samples`) and disparities. A drag inside one
    cell copies no view into the kernel's memory (they stay there)."""
    info = _kernel_tool("web_blend_kernel.mjs", name, sample_files, tmp_path)
    assert info["same"] and info["differ"] == 0, info
    assert info["copies"] > 0 and info["drag_copies"] == 0 and info["costs_checked"] >= 3, info


@pytest.mark.parametrize("name", ["rlfc_tx2_lossless_ga16.lfc", "rlfc_tx4_weighted_rgb8.lfc", "rlfc_tx5_warped_rgb8.lfc",
                                  "rlfc_tx6_alpha_rgba8.lfc", "grey", "sample"])
def test_prediction_kernel_matches_the_loops_bit_for_bit(name, sample_files, tmp_path):
    """A view built on WebAssembly SIMD (predict_kernel.wat: the prediction four plane samples at a
    time, windows across the edge through a clamped copy; the residual blocks' dequantization,
    inverse transform and clipping) makes the loops' planes (_predictTb, _addResidual) integer for
    integer, every view at both levels, key views included: 1 (grey), 2 (grey+alpha, 16-bit,
    lossless: bypassed planes), 3 (weighted prediction; per-view warps; the bundled crop's residual
    blocks) and 4 (RGBA) planes. The key views go into the kernel's memory."""
    info = _kernel_tool("web_predict_kernel.mjs", name, sample_files, tmp_path)
    if name == "rlfc_tx4_weighted_rgb8.lfc":
        assert info["weighted"]
    assert info["predicted"] > 0 and info["copies"] > 0, info
    assert info["same"] and info["differ"] == 0, info
    assert info["fallback_same"] and info["fallback_copies"] == 0, info


def test_prediction_kernel_refuses_damaged_streams_as_the_loops_do(tmp_path):
    """Block streams damaged in place (bytes and bits of tx.blocks changed, checksums made valid
    again: tools.fuzz's mutations): the kernel's parse (predict_kernel.wat) gives every view the
    loops' planes or the loops' FormatError, word for word (parseBlock's seven errors)."""
    from tools.fuzz import join_file, split_file

    meta, secs = split_file((GOLDEN / "rlfc_tx5_warped_rgb8.lfc").read_bytes())
    names = [n for n, _ in secs]
    blocks = bytearray(secs[names.index("tx.blocks")][1])
    rng = np.random.default_rng(7)
    outcomes = set()
    for m in range(24):
        b = bytearray(blocks)
        for at in rng.integers(0, len(b), 1 + m % 3):
            b[at] ^= 1 << int(rng.integers(8)) if m % 2 else int(rng.integers(1, 256))
        path = tmp_path / f"m{m}.lfc"
        path.write_bytes(join_file(meta, [(n, bytes(b) if n == "tx.blocks" else d) for n, d in secs]))
        got = subprocess.run([NODE, str(ROOT / "tools" / "web_predict_kernel.mjs"), str(path), "0"],
                             capture_output=True, text=True, timeout=300)
        assert got.returncode == 0, got.stderr[-3000:]
        info = json.loads(got.stdout.strip().splitlines()[-1])
        assert info["same"] and info["kernel"], (m, info)
        outcomes.add(info["first_error"].split(": ")[-1] if info.get("errors") else "decoded")
    assert len(outcomes) >= 2, outcomes


def test_bad_files_get_typed_errors(tmp_path):
    good = (GOLDEN / "rlfc_tx2_lossy_rgba8.lfc").read_bytes()
    cases = {
        "truncated": (good[:-50], "truncated"),
        "flipped": (good[:-30] + bytes([good[-30] ^ 4]) + good[-29:], "checksum"),
        "not_lfc": (b"hello world" * 10, "not an .lfc"),
        "empty": (b"", "too short"),
    }
    for name, (data, words) in cases.items():
        p = tmp_path / f"{name}.lfc"
        p.write_bytes(data)
        info = run_js(p, tmp_path / name)
        assert not info["ok"] and info["name"] == "FormatError" and words in info["message"], (name, info)
    for name, words in (("rlfc_dcp_lossy_rgb8", "dcp"), ("rlfc_tx_lossy_rgb8", "version 1"), ("lfn_tiny_rgba8", "lfn")):
        info = run_js(GOLDEN / f"{name}.lfc", tmp_path / name)
        assert info["name"] == "UnsupportedError" and words in info["message"], info


def test_views_coded_alone_as_jpeg2000_agree(tmp_path):
    """A file whose predicted views were cheaper coded alone: they are JPEG 2000 intra key views
    appended to the key order (and predicted keys made intra); the JavaScript decoder reads them
    like the Python one (JPEG 2000's float inverse: within 1)."""
    from formats.codec_api import EncodeOptions
    from rlfc import encode
    from tests.rlfc.helpers import open_encoded
    from tests.rlfc.test_tx import _unrelated_grid

    lf = _unrelated_grid(rows=3, cols=3)
    e = encode(lf, EncodeOptions(profile="tx", target_psnr=48))
    d, blob = open_encoded(lf, e)
    assert len(d.core.img_of) > 1 and len(d.core.lay.keys) > 4       # views past the 2×2 planned keys
    path = tmp_path / "alone.lfc"
    path.write_bytes(blob)
    differ = assert_same_planes(path, tmp_path / "out", exact=False)
    assert differ <= 0.001 * d.rows * d.cols * d.height * d.width * d.P


def test_wide_views_agree(tmp_path):
    """Key-view row streams of more than 1000 8×8 blocks (views wider than 4000 px): the
    JavaScript decoder reads the same planes."""
    from tests.rlfc.helpers import open_encoded
    from tests.rlfc.test_tx import _wide_lf, tx

    lf = _wide_lf(8, 4400)
    _, blob = open_encoded(lf, tx(lf, step=4.0))
    path = tmp_path / "wide.lfc"
    path.write_bytes(blob)
    assert_same_planes(path, tmp_path / "out")


def test_thumbnail_levels_beyond_any_block_mean_are_refused_as_in_python(tmp_path):
    """tools.fuzz seed 59: a thumbnail step raised to 16001 (Python's int32 upsampling overflowed,
    JavaScript's doubles did not); both readers now refuse the file with the same words."""
    from tools.fuzz import split_file
    from tests.test_fuzz_files import _rebuild

    meta, secs = split_file((GOLDEN / "rlfc_tx2_lossless_ga16.lfc").read_bytes())
    meta["config"]["tx"]["thumb_step16"] = 16001
    p = tmp_path / "thumb.lfc"
    p.write_bytes(_rebuild(meta, secs))
    info = run_js(p, tmp_path / "out")
    words = "thumbnail level times the thumbnail step"
    assert not info["ok"] and info["name"] == "FormatError" and words in info["message"], info
    with pytest.raises(Exception, match=words):
        open_decoder(open_lfc(p))


def test_disparity_escapes_agree(tmp_path):
    """Maps whose corrections escape (cells that disagree by two pixels or more per view step,
    every escape digit position in use: tx.maps version 3, one context per digit position):
    the JavaScript decoder reads the same maps, so the same planes."""
    from tests.rlfc.helpers import open_encoded
    from tests.rlfc.test_tx import _wide_lf, tx
    from tools.make_golden import far_maps

    lf = _wide_lf(40, 96)
    with far_maps() as made:
        e = tx(lf, step=4.0)
    d, blob = open_encoded(lf, e)
    raw = bytes(d.file.container.read("tx.maps"))
    corr = np.abs(made["disp"] - made["base"][None, :])
    assert raw[0] == 3 and (corr >= 31).sum() > 20 and (corr >= 31 + 4096).any()   # escapes, all digits
    assert np.array_equal(d.core.disp, made["disp"])
    path = tmp_path / "escapes.lfc"
    path.write_bytes(blob)
    assert_same_planes(path, tmp_path / "out")


def test_maps_are_decoded_when_a_view_needs_them(tmp_path):
    """The JavaScript decoder opens a file without decoding its disparity maps (as the Python
    decoder: an open decodes none of them) and decodes each map when a view first needs it. A map
    stream damaged in place (checksums made valid again) is then refused by exactly the views
    that read it, with a FormatError, in JavaScript as in Python, while the other views still
    decode to Python's planes."""
    from formats.errors import FormatError
    from tools.fuzz import join_file, split_file

    src = GOLDEN / "rlfc_tx4_weighted_rgb8.lfc"
    out = tmp_path / "clean"
    got = subprocess.run([NODE, str(HERE / "web_each_view.mjs"), str(src), str(out)], capture_output=True,
                         text=True, timeout=300)
    info = json.loads(got.stdout.strip().splitlines()[-1])
    assert info["ok"] and info["mapsAfterOpen"] == 0 and info["nMaps"] > 2
    assert all(v["ok"] for v in info["views"]) and info["views"][-1]["maps"] == info["nMaps"]
    assert 0 < min(v["maps"] for v in info["views"] if v["cell"] >= 0) < info["nMaps"]   # one at a time
    meta, secs = split_file(src.read_bytes())
    names = [n for n, _ in secs]
    maps = bytearray(secs[names.index("tx.maps")][1])
    refused = set()
    for k in range(12):                              # bytes of the last map streams, changed
        b = bytearray(maps)
        b[len(b) - 1 - 2 * k] ^= 0x5A
        path = tmp_path / f"m{k}.lfc"
        path.write_bytes(join_file(meta, [(n, bytes(b) if n == "tx.maps" else d) for n, d in secs]))
        got = subprocess.run([NODE, str(HERE / "web_each_view.mjs"), str(path), str(tmp_path / f"o{k}")],
                             capture_output=True, text=True, timeout=300)
        info = json.loads(got.stdout.strip().splitlines()[-1])
        assert info["ok"], info                      # the open reads no map
        d = open_decoder(open_lfc(path))
        for v, js in enumerate(info["views"]):
            try:
                py = d.decode_views([v], planes=True)[0]
            except FormatError:
                py = None
            assert js["ok"] == (py is not None), (k, v, js)
            if py is None:
                assert js["name"] == "FormatError" and "tx.maps" in js["message"], js
                refused.add((k, v))
            else:
                a = np.fromfile(tmp_path / f"o{k}" / f"view_{v}.bin", np.int32).reshape(info["Hp"], info["Wp"], info["P"])
                np.testing.assert_array_equal(a[:d.height, :d.width], py, err_msg=f"damage {k} view {v}")
    cases = {k for k, _ in refused}
    assert cases and any(len([1 for kk, _ in refused if kk == k]) < 16 for k in cases), refused


def test_open_and_key_views_read_in_few_requests(tmp_path):
    """Over HTTP each read is a round trip: opening reads the file's first 4 KiB (the header,
    the section table, the metadata) and then the sections it needs in one request per run of
    them (at most 3 in all, against 8 one section at a time), and a
    transform-coded key view's rows (2 streams a row, in a file of 256-byte checksum chunks: a
    key's rows span several) come in one request, not one per chunk as row after row is read."""
    from formats.cli import main
    from formats.lfcfile import write_lfc

    f = tmp_path / "split.lfc"
    assert main(["encode", str(ROOT / "samples" / "dino_crop"), str(f), "--quant", "3", "--intra-codec", "tx",
                 "--key-split", "2", "--quiet"]) == 0
    g = open_lfc(f)
    small = tmp_path / "small_chunks.lfc"
    write_lfc(small, g.codec, g.meta["codec_version"], g.meta["config"], g.meta["scene"],
              [(n, g.container.read(n)) for n in g.container.sections if n != "meta"], chunk_size=256)
    got = subprocess.run([NODE, str(HERE / "web_requests.mjs"), str(small)], capture_output=True, text=True,
                         timeout=300)
    assert got.returncode == 0, got.stderr[-3000:]
    info = json.loads(got.stdout.strip().splitlines()[-1])
    assert info["open"] <= 3, info
    coded = [k for k in info["keys"] if k["transform"]]
    assert coded and all(k["requests"] <= 1 for k in coded), info


def test_range_source_reads_the_size_with_the_first_bytes(tmp_path):
    """lfc.js's RangeSource (a fake fetch serving a file's ranges): the size, version and first
    4 KiB come in one range GET, which the open then reads without a request of its own (no
    HEAD); a server whose Content-Range gives no total size (cross-origin, not exposed) takes a
    HEAD as before, its first bytes kept. The same planes either way."""
    from formats.cli import main

    f = tmp_path / "d.lfc"
    assert main(["encode", str(ROOT / "samples" / "dino_crop"), str(f), "--quant", "3", "--intra-codec", "tx",
                 "--quiet"]) == 0
    runs = {}
    for mode in ("total", "nototal"):
        got = subprocess.run([NODE, str(HERE / "web_range_source.mjs"), str(f), mode], capture_output=True, text=True,
                             timeout=300)
        assert got.returncode == 0, got.stderr[-3000:]
        runs[mode] = json.loads(got.stdout.strip().splitlines()[-1])
    for mode, r in runs.items():
        assert r["same"] and r["size"] == r["n"] == f.stat().st_size, (mode, r)
        assert r["calls"][0] == "GET bytes=0-4095" and r["calls"].count("GET bytes=0-4095") == 1, (mode, r)
    assert "HEAD" not in runs["total"]["calls"] and "HEAD" in runs["nototal"]["calls"]
