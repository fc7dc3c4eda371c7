"""Light field networks in the browser viewer (formats/web/lfn.js), run under Node: the same
pixels as the Python renderer (within one grey level: JS computes in doubles, torch in float32)
for captured views, continuous grid positions, orbits about a posed capture's pivot, fractional
network sizes and reduced scales; networks grown section by section equal networks opened
whole; typed errors for bad files. Skipped with the reason where Node.js is not installed."""
from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
import torch

from formats.container import build_container
from formats.lfcfile import encode_meta, lfc_bytes, open_lfc
from formats.lightfield import LightField
from lfn_stream import CODEC_VERSION, MOVED_KEYS, LfnConfig, LfnRenderer, NestedLFN, OccupancyNet, to_sections
from lfn_stream.cameras import captured_poses, scene_pivot
from lfn_stream.pack import step_offsets

HERE = Path(__file__).resolve().parent
GOLDEN = HERE.parents[0] / "data" / "golden"
NODE = shutil.which("node")
pytestmark = pytest.mark.skipif(NODE is None, reason="Node.js is not installed (apt-get install nodejs)")


def run_js(path: Path, out: Path, cams, first=None, wasm: bool = True) -> dict:
    import os

    env = dict(os.environ)
    if first is not None:
        env["LFN_FIRST_NEURONS"] = str(first)
    if not wasm:
        env["LFN_NO_WASM"] = "1"
    got = subprocess.run([NODE, str(HERE / "web_lfn.mjs"), str(path), str(out), *cams], capture_output=True,
                         text=True, timeout=600, env=env)
    assert got.returncode == 0, got.stderr[-3000:]
    return json.loads(got.stdout.strip().splitlines()[-1])


def orbit_c2w(n: int, radius: float = 4.0) -> np.ndarray:
    """(1, n, 4, 4) cameras on a tilted ring looking at (0.2, -0.1, 0.3), OpenGL axes, z up."""
    target = np.array([0.2, -0.1, 0.3])
    out = np.zeros((1, n, 4, 4))
    for i in range(n):
        a = 2 * np.pi * i / n
        o = target + radius * np.array([np.cos(a), np.sin(a), 0.5 + 0.2 * np.sin(3 * a)])
        f = (target - o) / np.linalg.norm(target - o)
        r = np.cross(f, [0, 0, 1.0])
        r /= np.linalg.norm(r)
        u = np.cross(r, f)
        out[0, i, :3, :3] = np.stack([r, u, -f], 1)
        out[0, i, :3, 3] = o
        out[0, i, 3, 3] = 1
    return out


def lfn_file(tmp: Path, channels: int, dtype=np.uint8, weights="fp16", posed=True, occ=True, seed=0,
             display=None, display_scales=None, out_bias=False) -> Path:
    torch.manual_seed(seed)
    cfg = LfnConfig(depth=4, min_neurons=6, max_neurons=20, occupancy_neurons=8 if occ else 0)
    m = NestedLFN(cfg)
    with torch.no_grad():   # non-trivial LayerNorm parameters; outputs spread over [0, 1]
        for p in list(m.gammas) + list(m.betas) + list(m.biases):
            p.uniform_(-1, 1)
        m.out_w.mul_(8)
        if out_bias:
            m.out_b.uniform_(-2, 2)
    o = OccupancyNet(8) if occ else None
    if o is not None:       # about half of the rays rejected (sigmoid ≤ 0.1 ⇔ logit ≤ −2.197)
        with torch.no_grad():
            o.net[4].weight.mul_(10)
            o.net[4].bias.fill_(-2.2)
    views = np.zeros((1, 6, 24, 30, channels), dtype) if posed else np.zeros((3, 4, 24, 30, channels), dtype)
    if posed:
        c2w = orbit_c2w(6)
        lf = LightField(views=views, positions=c2w[..., :3, 3], c2w=c2w, focal=(28.0, 27.0), principal=(15.5, 11.0),
                        layout="posed")
    else:
        r, c = np.meshgrid(np.arange(3), np.arange(4), indexing="ij")
        pos = np.stack([c * 0.3, -r * 0.25, np.zeros_like(r, float)], -1)
        lf = LightField(views=views, positions=pos, focal=(30.0, 30.0))
    config, sections = to_sections(m, o, {"norm": {"centre": [0.1, 0.0, 0.2], "radius": 2.5}, "display": display,
                                          "display_scales": display_scales}, weights)
    sections = [(n, d, 96) if n == "lfn.steps" else (n, d) for n, d, *_ in sections]   # steps span chunks
    p = tmp / f"net_{channels}_{np.dtype(dtype).name}_{weights}_{posed}.lfc"
    p.write_bytes(lfc_bytes("lfn", CODEC_VERSION, config, lf.geometry(), sections, more=MOVED_KEYS))
    return p


def compare(path: Path, out: Path, cams, py_poses, first=None):
    info = run_js(path, out, [c[0] for c in cams], first)
    assert info["ok"], info
    r = LfnRenderer(open_lfc(path), device="cpu")
    for i, ((spec, neurons, scale), pose) in enumerate(zip(cams, py_poses)):
        got = info["renders"][i]
        np.testing.assert_allclose(np.array(got["pose"]).reshape(4, 4), pose, atol=1e-12)
        want = r.to_pixels(r.render_pose(pose, neurons, scale, native=spec.endswith(",native")))
        js = np.fromfile(out / f"render_{i}.bin", want.dtype).reshape(want.shape)
        diff = np.abs(js.astype(np.int64) - want)
        peak = np.iinfo(want.dtype).max
        assert diff.max() <= max(1, peak // 255), (path.name, i, diff.max())
        assert (diff > 0).mean() < 0.02, (path.name, i, (diff > 0).mean())
    return info, r


@pytest.mark.parametrize("name", ["lfn_tiny_rgba8", "lfn3_tiny_rgba8"])     # codec versions 1 and 3
def test_golden_network_matches_python_exactly(tmp_path, name):
    path = GOLDEN / f"{name}.lfc"
    r = LfnRenderer(open_lfc(path), device="cpu")
    cams = [("view,5,max,1", 8.0, 1.0), ("grid,1.5,2.25,6.5,1", 6.5, 1.0), ("view,0,4,auto", 4.0, None)]
    poses = [r.pose(1, 1), r.grid_pose(1.5, 2.25), r.pose(0, 0)]
    info, _ = compare(path, tmp_path, cams, poses)
    assert [x["h"] for x in info["renders"]] == [29, 29, round(29 / 8)]


@pytest.mark.parametrize("channels,dtype,weights", [(4, np.uint8, "fp16"), (3, np.uint8, "fp32"),
                                                     (2, np.uint16, "fp16"), (1, np.uint16, "fp32")])
def test_posed_networks_match_python(tmp_path, channels, dtype, weights):
    path = lfn_file(tmp_path, channels, dtype, weights)
    r = LfnRenderer(open_lfc(path), device="cpu")
    cams = [("view,2,max,1", 20.0, 1.0), ("orbit,4,25,-10,13.5,1", 13.5, 1.0), ("orbit,1,-140,30,9.25,auto", 9.25, None)]
    poses = [r.pose(0, 2), r.orbit_pose(0, 4, 25, -10), r.orbit_pose(0, 1, -140, 30)]
    info, _ = compare(path, tmp_path, cams, poses)
    pivot, up = scene_pivot(captured_poses(r.geom.positions, r.geom.c2w), r.norm["centre"])
    np.testing.assert_allclose(info["pivot"], pivot, atol=1e-9)
    np.testing.assert_allclose(info["up"], up, atol=1e-12)
    np.testing.assert_allclose(pivot, [0.2, -0.1, 0.3], atol=1e-6)     # the cameras' common target
    if channels in (2, 4):   # the occupancy net skipped rays in both renderers
        assert 0.1 * 24 * 30 < info["renders"][0]["evaluated"] < 0.9 * 24 * 30


def test_grown_network_equals_the_whole_one(tmp_path):
    path = lfn_file(tmp_path, 3, posed=False, occ=False)
    r = LfnRenderer(open_lfc(path), device="cpu")
    cams = [("grid,0.4,2.7,7,1", 7.0, 1.0), ("grid,2,3,11.5,0.5", 11.5, 0.5), ("view,6,max,1", 20.0, 1.0)]
    poses = [r.grid_pose(0.4, 2.7), r.grid_pose(2, 3), r.pose(1, 2)]
    info, _ = compare(path, tmp_path, cams, poses, first=6)
    assert info["opened"] == 6 and [x["neurons"] for x in info["renders"]] == [7, 12, 20]
    assert run_js(path, tmp_path / "whole", [c[0] for c in cams])["ok"]
    for i in range(3):
        assert (tmp_path / f"render_{i}.bin").read_bytes() == (tmp_path / "whole" / f"render_{i}.bin").read_bytes()


def test_display_ladder_shows_the_same_size_as_python(tmp_path):
    """config.display: opened with the steps up to N neurons, the JS reader shows the largest
    ladder size ≤ N, as LfnRenderer.display_neurons does for a prefix holding N neurons."""
    ladder = [6, 7, 10, 11, 15, 20]
    path = lfn_file(tmp_path, 3, posed=False, occ=False, display=ladder)
    r = LfnRenderer(open_lfc(path), device="cpu")
    assert r.display == ladder
    for first, shown in ((9, 7.0), (14, 11.0), (20, 20.0)):
        info, _ = compare(path, tmp_path / str(first), [("grid,1,2,display,1", shown, 1.0)], [r.grid_pose(1, 2)],
                          first=first)
        assert info["renders"][0]["shown"] == shown and info["opened"] == first


def test_display_ladders_per_scale_show_the_same_size_as_python(tmp_path):
    """config.display_scales: at a render scale the JS reader shows the largest size the held
    steps reach of the ladder measured at the nearest display scale, as
    LfnRenderer.display_neurons_at does; without a scale, config.display."""
    scales = [[0.25, [6, 8, 9]], [1.0, [6, 7, 10, 11, 15, 18]]]
    path = lfn_file(tmp_path, 3, posed=False, occ=False, display=[6, 7, 10, 11, 15, 18, 20], display_scales=scales)
    r = LfnRenderer(open_lfc(path), device="cpu")
    for first in (9, 14, 20):
        part = LfnRenderer(open_lfc(path), device="cpu", max_neurons=first)
        cams = [(f"grid,1,2,display,{sc}", part.display_neurons_at(sc), sc) for sc in (0.25, 0.4, 1.0)]
        cams.append(("grid,1,2,display,auto", part.display_neurons, None))
        info, _ = compare(path, tmp_path / str(first), cams, [r.grid_pose(1, 2)] * 4, first=first)
        assert [x["shown"] for x in info["renders"]] == [c[1] for c in cams]
    assert [c[1] for c in cams] == [9, 9, 18, 20]


@pytest.mark.parametrize("channels,occ", [(4, True), (3, False), (2, True)])
def test_native_renders_match_python(tmp_path, channels, occ):
    """render(..., {native: true}): a network whose display ladders say it was trained at 1/4 of
    the views' size runs on a lattice every 4 pixels at full size (2 at half size, fractional
    sizes too), upsampled with OpenCV's pixel-centre convention and the silhouette cut per
    pixel: the pixels of LfnRenderer.render_pose(..., native=True), with a sixteenth of the
    network passes; at the network's own scale the render is the dense one."""
    scales = [[0.125, [6, 9]], [0.25, [6, 9, 14, 20]]]
    path = lfn_file(tmp_path, channels, occ=occ, display_scales=scales)
    r = LfnRenderer(open_lfc(path), device="cpu")
    assert r.native_stride(20, 1.0) == 4 and r.native_stride(20, 0.5) == 2 and r.native_stride(20, 0.25) == 1
    cams = [("view,2,max,1,native", 20.0, 1.0), ("orbit,4,25,-10,13.5,0.5,native", 13.5, 0.5),
            ("orbit,1,-140,30,9.25,1,native", 9.25, 1.0), ("view,3,max,0.25,native", 20.0, 0.25)]
    poses = [r.pose(0, 2), r.orbit_pose(0, 4, 25, -10), r.orbit_pose(0, 1, -140, 30), r.pose(0, 3)]
    info, _ = compare(path, tmp_path, cams, poses)
    assert [x["stride"] for x in info["renders"]] == [r.native_stride(n, s) for _, n, s in cams]
    assert info["renders"][2]["stride"] == 8 and info["renders"][3]["stride"] == 1
    assert info["renders"][0]["evaluated"] <= 6 * 8          # the 6×8 lattice of a 24×30 view
    assert run_js(path, tmp_path / "dense", ["view,3,max,0.25"])["ok"]
    assert (tmp_path / "render_3.bin").read_bytes() == (tmp_path / "dense" / "render_0.bin").read_bytes()


@pytest.mark.parametrize("channels,occ", [(4, True), (3, False)])
def test_foveated_renders_match_python(tmp_path, channels, occ):
    """renderMip(pose, foveationMap(gaze)): the mip render of LfnRenderer.render_pose_lod_mip
    (pose, foveation_map(gaze, dither=False, scale=S)) within one grey level: lattices every 2,
    4 and 8 pixels at the sizes mip_neurons gives, blended, silhouettes cut per pixel; on the
    network's own grid too (native); the fovea exactly the JS dense render's pixels; fewer
    network passes than the dense render."""
    path = lfn_file(tmp_path, channels, occ=occ, display_scales=[[0.25, [6, 9, 14, 20]]])
    r = LfnRenderer(open_lfc(path), device="cpu")
    cams = [("view,2,max,2,fovea:30:24", r.pose(0, 2), (30, 24), 2.0, False),
            ("orbit,4,25,-10,max,3,fovea:20:60", r.orbit_pose(0, 4, 25, -10), (20, 60), 3.0, False),
            ("orbit,1,-140,30,max,2,native,fovea:45:10", r.orbit_pose(0, 1, -140, 30), (45, 10), 2.0, True),
            ("view,3,max,1,fovea:-4:30", r.pose(0, 3), (-4, 30), 1.0, False)]
    info = run_js(path, tmp_path, [c[0] for c in cams])
    assert info["ok"], info
    dense = run_js(path, tmp_path / "dense", [c[0].rsplit(",", 1)[0] for c in cams])
    fovea = 0
    for i, (spec, pose, gaze, scale, native) in enumerate(cams):
        lod = r.foveation_map(gaze, dither=False, scale=scale)
        want = r.to_pixels(r.render_pose_lod_mip(pose, lod, native=native))
        js = np.fromfile(tmp_path / f"render_{i}.bin", want.dtype).reshape(want.shape)
        diff = np.abs(js.astype(np.int64) - want)
        assert diff.max() <= 1 and (diff > 0).mean() < 0.02, (spec, diff.max(), (diff > 0).mean())
        got = info["renders"][i]
        assert got["levels"] >= 3 and got["evaluated"] < dense["renders"][i]["evaluated"], (spec, got)
        if not native:                     # pixels on the full-density level alone: render()'s
            m = np.clip(r.mip_levels(lod, 3) + 0.25, 0, 3)
            pure = (np.floor(m) == 0) & (np.clip((m - np.floor(m) - 0.5) / 0.25 + 0.5, 0, 1) == 0)
            full = np.fromfile(tmp_path / "dense" / f"render_{i}.bin", want.dtype).reshape(want.shape)
            assert np.array_equal(js[pure], full[pure]), spec
            fovea += int(pure.sum())
    assert fovea >= 100                    # (the last gaze lies outside its frame: no fovea)
    assert len(set((tmp_path / "render_0.bin").read_bytes())) >= 10          # not a constant


@pytest.mark.parametrize("channels,dtype,weights,occ", [(4, np.uint8, "fp16", True), (3, np.uint8, "fp32", False),
                                                         (1, np.uint16, "fp16", True)])
def test_webassembly_layers_give_the_same_pixels_as_the_js_loops(tmp_path, channels, dtype, weights, occ):
    """The dense layers on WebAssembly SIMD (lfn_kernel.wat) sum in the JS loops' order with the
    same roundings: byte-identical renders at full, fractional (widths not a multiple of 4) and
    base sizes, grown networks included."""
    path = lfn_file(tmp_path, channels, dtype, weights, occ=occ, display_scales=[[0.25, [6, 9, 14, 20]]])
    cams = ["view,2,max,1", "orbit,4,25,-10,13.5,1", "orbit,1,-140,30,9.25,auto", "view,0,6,1", "view,5,17,1,native"]
    fast = run_js(path, tmp_path / "wasm", cams, first=7)
    slow = run_js(path, tmp_path / "js", cams, first=7, wasm=False)
    assert fast["ok"] and slow["ok"] and fast["wasm"] and not slow["wasm"]
    seen = set()
    for i in range(len(cams)):
        a = (tmp_path / "wasm" / f"render_{i}.bin").read_bytes()
        assert a == (tmp_path / "js" / f"render_{i}.bin").read_bytes(), cams[i]
        assert len(set(a)) >= 3, cams[i]                          # not a constant
        seen |= set(a)
    assert len(seen) >= 20


def r_cfg(f):
    return LfnConfig.from_dict(f.meta["config"]["network"], f.meta["codec_version"])


def test_bad_networks_get_typed_errors(tmp_path):
    src = lfn_file(tmp_path, 3, posed=False, occ=False)
    f = open_lfc(src)
    meta = dict(f.meta)
    secs = [(n, bytes(f.container.read(n))) for n in f.container.sections if n != "meta"]

    def write(name, meta, secs):
        p = tmp_path / f"{name}.lfc"
        m = encode_meta(meta["codec"], meta["codec_version"], meta["config"], meta["scene"],
                        {"more": meta["more"]} if "more" in meta else None)
        p.write_bytes(b"".join(bytes(x) for x in build_container(m, secs)))
        return p

    at = int(step_offsets(r_cfg(f), "fp16")[3])       # step 3 inside lfn.steps
    cases = {
        "depth": ({**meta, "config": {**meta["config"], "network": {**meta["config"]["network"], "depth": 5}}}, secs,
                  "FormatError", "lfn.base"),
        "nan": (meta, [(n, d[:at] + b"\x00\x7e" + d[at + 2:]) if n == "lfn.steps" else (n, d) for n, d in secs],
                "FormatError", "NaN"),
        "steps": (meta, [(n, d[:-2]) if n == "lfn.steps" else (n, d) for n, d in secs], "FormatError", "lfn.steps"),
        "no-more": (meta, [(n, d) for n, d in secs if n != "meta.more"], "FormatError", "meta.more"),
        "bad-more": (meta, [(n, b"\x78\x9c" + d[2:-3]) if n == "meta.more" else (n, d) for n, d in secs],
                     "FormatError", "meta.more"),
        "more-keys": ({**meta, "more": ["scene.rows"]}, secs, "FormatError", "scene.rows"),
        "version": ({**meta, "codec_version": 9}, secs, "UnsupportedError", "version 9"),
        "display": ({**meta, "config": {**meta["config"], "display": [6, 12, 9, 20]}}, secs, "FormatError",
                    "config.display"),
        "display_scales": ({**meta, "config": {**meta["config"], "display_scales": [[0.5, [6, 21]]]}}, secs,
                           "FormatError", "config.display_scales"),
        "radius": ({**meta, "config": {**meta["config"], "norm": {"centre": [0, 0, 0], "radius": -1}}}, secs,
                   "FormatError", "radius"),
        "named-twice": ({**meta, "codec_version": 1, "config": {**meta["config"], "network": {
            **meta["config"]["network"], "min_width": meta["config"]["network"]["min_neurons"]}}}, secs,
            "FormatError", "twice"),
        "baseline-overflow": ({**meta, "scene": {**meta["scene"], "baseline": [1e308, 1.0]}}, secs,
                              "FormatError", "baseline"),
    }
    for name, (m, s, err, needle) in cases.items():
        info = run_js(write(name, m, s), tmp_path / name, ["view,0,max,1"])
        assert not info["ok"] and info["name"] == err and needle in info["message"], (name, info)


def test_tile_manifests_and_blend_weights_match_python(tmp_path):
    """tiles.js reads manifests as lfn_stream.tiles.read_manifest does (the same refusals) and
    blends the same tiles with the same weights."""
    from formats.errors import FormatError
    from lfn_stream.tiles import blend_weights, read_manifest

    rng = np.random.default_rng(3)
    good = {"format": "lfcodec-lfn-tiles", "version": 1, "band": 0.7,
            "tiles": [{"file": f"a/t{j}.lfc", "centre": rng.normal(size=3).tolist(), "views": [j]} for j in range(5)]}
    bad = [{**good, "version": 2}, {**good, "band": 5}, {**good, "tiles": []}, {**good, "format": "x"},
           {**good, "tiles": [{"file": "../t.lfc", "centre": [0, 0, 0]}]},
           {**good, "tiles": [{"file": "/abs.lfc", "centre": [0, 0, 0]}]},
           {**good, "tiles": [{"file": "t.lfc", "centre": [0, 0]}]}, [1, 2]]
    texts = [json.dumps(good)] + [json.dumps(b) for b in bad] + ["{not json", '{"format": "lfcodec-lfn-tiles", "version": 1, "tiles": [{"file": "t.lfc", "centre": [1e300, 0, 0]}]}']
    cams = rng.normal(scale=1.5, size=(40, 3)).tolist() + [good["tiles"][2]["centre"]]
    script = tmp_path / "t.mjs"
    script.write_text(f"""
const {{ readManifest, blendWeights }} = await import({json.dumps(str(HERE.parents[1] / "formats/web/tiles.js"))});
const texts = {json.dumps(texts)}, cams = {json.dumps(cams)};
const out = texts.map((t) => {{ try {{ const m = readManifest(new TextEncoder().encode(t), "m.json");
  return {{ ok: true, files: m.files, w: cams.map((p) => Array.from(blendWeights(m.centres, p, m.band))) }};
}} catch (e) {{ return {{ ok: false, name: e.name, message: e.message }}; }} }});
console.log(JSON.stringify(out));
""")
    got = subprocess.run([NODE, str(script)], capture_output=True, text=True, timeout=120)
    assert got.returncode == 0, got.stderr[-2000:]
    res = json.loads(got.stdout)
    for text, r in zip(texts, res):
        try:
            m = read_manifest(text.encode(), "m.json")
        except FormatError as e:
            assert not r["ok"] and r["name"] == "FormatError", (text, r, e)
            continue
        assert r["ok"] and r["files"] == m["files"], (text, r)
        want = np.stack([blend_weights(m["centres"], np.asarray(p), m["band"]) for p in cams])
        np.testing.assert_allclose(np.asarray(r["w"]), want, rtol=0, atol=1e-12)
        assert ((np.asarray(r["w"]) > 0) == (want > 0)).all()


def node_with_decoder(tmp: Path, path: Path, body: str) -> dict:
    """Run ``body`` (JavaScript) under Node with ``dec``, an LfnDecoder of ``path``, and
    ``LfnDecoder`` in scope; returns the JSON it prints."""
    web = HERE.parents[1] / "formats/web"
    script = tmp / "script.mjs"
    script.write_text(f"""
import fs from "fs";
const {{ LfcFile, BufferSource }} = await import({json.dumps(str(web / "lfc.js"))});
const {{ LfnDecoder }} = await import({json.dumps(str(web / "lfn.js"))});
const dec = await LfnDecoder.open(await LfcFile.open(new BufferSource(fs.readFileSync({json.dumps(str(path))})), "n"));
""" + body)
    out = subprocess.run([NODE, str(script)], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    return json.loads(out.stdout)


def test_webassembly_occupancy_logits_equal_the_js_ones(tmp_path):
    """The occupancy net on the kernel (batches of rays, sums started from their biases) gives
    _occupancyLogit's doubles exactly, for 1000 random rays (ones near the threshold included)."""
    res = node_with_decoder(tmp_path, lfn_file(tmp_path, 4), """
let seed = 1; const rnd = () => ((seed = (seed * 16807) % 2147483647) / 2147483647) * 2 - 1;
const n = 1000, rays = new Float64Array(6 * n).map(() => rnd());
const ws = dec._workspace(dec.neurons), got = [], want = [];
for (let a = 0; a < n; a += 64) {
  const cnt = Math.min(64, n - a), R4 = (cnt + 3) & ~3;
  for (let r = 0; r < R4; r++) for (let q = 0; q < 6; q++) ws.kern.X[q * 64 + r] = r < cnt ? rays[6 * (a + r) + q] : 0;
  const s = ws.kern.occupancy(R4);
  for (let r = 0; r < cnt; r++) { got.push(s[r]); want.push(dec._occupancyLogit(rays.subarray(6 * (a + r), 6 * (a + r) + 6), ws)); }
}
const inside = dec._occupiedAll(rays, n, ws);
console.log(JSON.stringify({ same: got.every((x, i) => Object.is(x, want[i])), spread: [Math.min(...want), Math.max(...want)],
  inside: inside.reduce((a, b) => a + b, 0) }));
""")
    assert res["same"] and res["spread"][0] < -2.2 < res["spread"][1] and 0 < res["inside"] < 1000, res


def test_webassembly_network_outputs_equal_the_js_ones(tmp_path):
    """The whole network on the kernel (layers, LayerNorms and the output layer, its sums started
    from the bias as the loop's) gives the JS loops' output doubles exactly: 1000 random rays at
    the full, a fractional and the base size."""
    res = node_with_decoder(tmp_path, lfn_file(tmp_path, 4, out_bias=True), """
let seed = 7; const rnd = () => ((seed = (seed * 16807) % 2147483647) / 2147483647) * 2 - 1;
const n = 1000, rays = new Float32Array(6 * n).map(() => rnd()), res = {};
for (const neurons of [dec.neurons, 13.5, dec.minN]) {
  const fast = new Float64Array(4 * n), slow = new Float64Array(4 * n);
  LfnDecoder.useWasm = true;
  const ws = dec._workspace(neurons);
  dec._forwardRays(ws, rays, n, null, fast);
  LfnDecoder.useWasm = false;
  dec._forwardRays(dec._workspace(neurons), rays, n, null, slow);
  res[neurons] = { kernel: Boolean(ws.kern), same: fast.every((x, i) => Object.is(x, slow[i])),
    spread: [Math.min(...fast), Math.max(...fast)] };
}
console.log(JSON.stringify(res));
""")
    for k, v in res.items():
        assert v["kernel"] and v["same"] and v["spread"][1] - v["spread"][0] > 0.3, (k, v)


@pytest.mark.skipif(not (HERE.parents[1] / "formats/web/node_modules/wabt").is_dir(),
                    reason="wabt is not installed (tools/build_web.sh installs it with npm ci)")
def test_the_kernel_modules_are_built_from_their_text():
    """formats/web/lfn_kernel.js and render_kernel.js hold what tools/build_kernels.mjs makes of
    lfn_kernel.wat and render_kernel.wat."""
    got = subprocess.run([NODE, str(HERE.parents[1] / "tools/build_kernels.mjs"), "--check"], capture_output=True,
                         text=True, timeout=120)
    assert got.returncode == 0, got.stdout + got.stderr
