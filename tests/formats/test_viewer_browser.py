"""The browser viewer in a real browser: headless Chromium (Debian's ``chromium``, driven by
Playwright's Python API) opens the page served from 127.0.0.1 by ``formats.serve`` (what
``lfcodec view`` runs), the page reads the .lfc by HTTP Range requests and decodes it in the
browser, and the canvas is compared with the Python decoder (a captured view: bit for bit) and
renderer (a novel view and a refocused one: within float rounding, tests.formats.frames). Light field networks render in the
page within one grey level of the Python renderer, their weights streamed as the level rises.
Bad files show a message.

Skipped with the reason where Chromium or Playwright is not installed (CI installs both)."""
from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from formats import open_decoder, open_lfc
from formats.serve import FileServer
from tests.formats.frames import assert_same_frame

ROOT = Path(__file__).resolve().parents[2]
CHROMIUM = os.environ.get("LFC_CHROMIUM") or shutil.which("chromium") or shutil.which("chromium-browser")
try:
    from playwright.sync_api import sync_playwright
except ImportError:                                     # pragma: no cover - depends on the machine
    sync_playwright = None
pytestmark = [
    pytest.mark.skipif(CHROMIUM is None, reason="Chromium is not installed (apt-get install chromium)"),
    pytest.mark.skipif(sync_playwright is None, reason="Playwright is not installed (pip install playwright)"),
]
FLAGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
         "--disable-component-update", "--disable-sync"]


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """A served folder: the bundled Lytro crop encoded with a JPEG 2000 key view, and with
    residual blocks (a small quantizer step); a corrupt copy and a truncated copy."""
    from formats.cli import main

    d = tmp_path_factory.mktemp("site")
    f = d / "dino.lfc"
    assert main(["encode", str(ROOT / "samples" / "dino_crop"), str(f), "--target-psnr", "36", "--intra-codec", "j2k",
                 "--quiet"]) == 0
    assert main(["encode", str(ROOT / "samples" / "dino_crop"), str(d / "res.lfc"), "--quant", "3", "--intra-codec",
                 "tx", "--quiet"]) == 0
    # every view coded alone as JPEG 2000 (the encoder's choice at high rates on views that
    # predict each other badly): no view has a map; the renderer's geometry is the shared one
    # (a synthetic 5×5 grid with 1 px of parallax per view step: the sample's is too small for
    # the geometry to show)
    from formats.lfcfile import lfc_bytes
    from rlfc.txencode import TxEncoder
    from rlfc.txparams import TxParams
    from tests.rlfc.helpers import make_lf

    rng = np.random.default_rng(3)
    base = rng.random((96, 120, 3))
    for ax in (0, 1):
        base = np.apply_along_axis(lambda m: np.convolve(m, np.ones(3) / 3, mode="same"), ax, base)
    base = (base - base.min()) / np.ptp(base)
    lf = make_lf(np.stack([np.stack([np.rint(base[r + 10:r + 74, c + 20:c + 100] * 255).astype(np.uint8)
                                     for c in range(5)]) for r in range(5)]))
    enc = TxEncoder(lf, TxParams(), None, 10.0)
    cfg, sections = enc.pack(enc.run_j2k(np.full(enc.n0, 40.0), 8.0))
    (d / "alone.lfc").write_bytes(lfc_bytes("rlfc", 1, cfg, lf.geometry(), sections))
    data = f.read_bytes()
    (d / "corrupt.lfc").write_bytes(data[:-40] + bytes([data[-40] ^ 1]) + data[-39:])
    (d / "cut.lfc").write_bytes(data[: len(data) // 2])
    (d / "secret.txt").write_text("a text file, not a light field\n" * 4)
    from tests.formats.test_web_lfn import lfn_file

    lfn_file(d, 3, posed=True, occ=False).rename(d / "net_posed.lfc")
    lfn_file(d, 3, posed=False, occ=False, seed=1).rename(d / "net_grid.lfc")
    lfn_file(d, 3, posed=True, seed=2, display_scales=[[0.25, [6, 9, 14, 20]]]).rename(d / "net_native.lfc")
    tile_set(d)
    with FileServer(d, viewer=True) as srv:
        yield srv, f


def tile_set(d: Path) -> None:
    """A tile set of two posed networks (different weights, the same cameras) centred on cameras 0
    and 2 of the six (set.json), and manifests a reader must refuse."""
    import json

    from lfn_stream.tiles import manifest_of, write_manifest
    from tests.formats.test_web_lfn import lfn_file, orbit_c2w

    for j in range(2):
        lfn_file(d, 3, posed=True, occ=j == 1, seed=5 + j).rename(d / f"set.tile{j:02d}.lfc")
    c = orbit_c2w(6)[0, :, :3, 3]
    write_manifest(d / "set.json", manifest_of(c[[0, 2]], 0.5, ["set.tile00.lfc", "set.tile01.lfc"], [[0, 1], [1, 2, 3]]))
    m = json.loads((d / "set.json").read_text())
    m["tiles"][1]["file"] = "../net_posed.lfc"
    (d / "escape.json").write_text(json.dumps(m))
    m["tiles"][1]["file"] = "net_grid.lfc"                  # another scene: refused when first blended
    (d / "mixed.json").write_text(json.dumps(m))


@pytest.fixture(scope="module")
def page(site):
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, headless=True, args=FLAGS)
        pg = browser.new_page()
        yield pg
        browser.close()


def open_viewer(page, srv, name: str, query: str = "") -> str:
    page.goto(srv.viewer_url(name) + query)
    page.wait_for_function("document.body.dataset.state !== 'loading'", timeout=120_000)
    return page.evaluate("document.body.dataset.state")


def canvas_rgb(page) -> np.ndarray:
    w, h, data = page.evaluate("""() => { const c = document.getElementById('view');
        const d = c.getContext('2d').getImageData(0, 0, c.width, c.height);
        return [c.width, c.height, Array.from(d.data)]; }""")
    return np.asarray(data, np.uint8).reshape(h, w, 4)[..., :3]


#: the cameras (s, t, focus, aperture, robust) the pixel-equality tests show: robust, not robust,
#: refocused, a synthetic aperture
CAMS = [(1.4, 2.7, "null", 0.0, "true"), (2.5, 1.5, "null", 0.0, "false"), (2.2, 2.1, "0.5", 0.0, "true"),
        (2.0, 2.0, "1.0", 1.5, "true")]


def show_cams(page) -> list:
    """Each of CAMS shown in the open page: [(canvas RGB, show()'s info)]."""
    out = []
    for s, t, focus, ap, robust in CAMS:
        info = page.evaluate(f"lfcViewer.show({s}, {t}, {{focus: {focus}, aperture: {ap}, robust: {robust}}})")
        out.append((canvas_rgb(page), info))
    return out


def preview_pixels(page) -> np.ndarray:
    """The page renderer's bilinear preview at the first of CAMS (its pixels, flat)."""
    return np.asarray(page.evaluate("""async () => {
        const f = await lfcViewer.renderer.render(1.4, 2.7, {cubic: false}); return Array.from(f.pixels); }"""))


def drag(page) -> None:
    """Drag across the canvas (up and to the left) and wait for the frame."""
    box = page.locator("#view").bounding_box()
    page.mouse.move(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
    page.mouse.down()
    page.mouse.move(box["x"] + box["width"] / 4, box["y"] + box["height"] / 3, steps=5)
    page.mouse.up()
    page.wait_for_function("!lfcViewer.state.busy")


@pytest.mark.parametrize("name", ["dino.lfc", "res.lfc"])
def test_viewer_matches_python(site, page, name):
    srv, f = site
    f = f.parent / name
    assert open_viewer(page, srv, f.name) == "ready", page.inner_text("#error")
    d = open_decoder(open_lfc(f))
    assert bool(d.core.img_of) == (name == "dino.lfc")    # a JPEG 2000 key view in the browser
    assert (d.core.coded.sum() > 0) == (name == "res.lfc")  # residual blocks in the browser
    info = page.evaluate("lfcViewer.show(4, 4)")          # a captured view
    got = canvas_rgb(page)
    want = d.decode_view(4, 4)
    # JPEG 2000's float 9/7 inverse: OpenJPEG/wasm and imagecodecs may differ by 1 at a few samples
    assert np.abs(got.astype(int) - want).max() <= 1 and (got != want).mean() < 0.001
    r = d.renderer()
    for s, t, focus, ap in ((3.4, 5.7, None, 0.0), (4.0, 4.0, 1.0, 2.0)):
        arg = "null" if focus is None else focus
        page.evaluate(f"lfcViewer.show({s}, {t}, {{focus: {arg}, aperture: {ap}}})")
        assert_same_frame(r.render(s, t, focus, ap), canvas_rgb(page))
    # byte ranges, not one download: never more bytes than the file; a file past the 4 KiB an
    # open reads ahead (lfc.js EARLY_BYTES: header, table, metadata) in several requests
    size = f.stat().st_size
    assert info["bytesFetched"] <= size and (info["requests"] > 2 if size > 4096 else info["requests"] >= 1)
    stats = page.inner_text("#stats")
    assert "bytes fetched" in stats and "view cache" in stats and "frame" in stats


@pytest.mark.parametrize("name", ["dino.lfc", "alone.lfc"])
def test_novel_views_blend_on_workers_with_the_same_pixels(site, page, name):
    """The page blends a novel view's rows on its thread and Web Workers (render_pool.js; &workers=2:
    the page and one worker; the crops are small, so the size threshold is lowered here): the
    canvas is the one the page's own thread draws
    (&workers=0), bit for bit, for each option set and for bilinear previews; a camera moving
    within one cell sends the workers no view again; a worker that cannot load leaves the frame
    to the page's thread."""
    srv, _ = site
    got = {}
    for query in ("&workers=2", "&workers=0"):
        assert open_viewer(page, srv, name, query) == "ready", page.inner_text("#error")
        page.evaluate("lfcViewer.renderer.poolMinPixels = 0")
        for i, (canvas, info) in enumerate(show_cams(page)):
            got[query, i] = canvas, info["workers"]
        got[query, "preview"] = preview_pixels(page), 0
        if query == "&workers=2":
            assert "worker" in page.inner_text("#stats")
            sent = page.evaluate("""async () => { const r = lfcViewer.renderer, p = r.pool; let n = 0;
                for (const w of p.workers) { const post = w.postMessage.bind(w);
                  w.postMessage = (m, tr) => { n += Object.keys(m.send).length; post(m, tr); }; }
                await r.render(1.45, 2.75); await r.render(1.5, 2.8); return n; }""")
            assert sent == 0
    for k in range(len(CAMS)):
        assert got["&workers=2", k][1] == 1 and got["&workers=0", k][1] == 0
        assert np.array_equal(got["&workers=2", k][0], got["&workers=0", k][0]), CAMS[k]
    assert np.array_equal(got["&workers=2", "preview"][0], got["&workers=0", "preview"][0])
    page.route("**/render_worker.js", lambda route: route.abort())
    try:
        assert open_viewer(page, srv, name, "&workers=2") == "ready", page.inner_text("#error")
        page.evaluate("lfcViewer.renderer.poolMinPixels = 0")
        s, t, focus, ap, robust = CAMS[0]
        info = page.evaluate(f"lfcViewer.show({s}, {t}, {{focus: {focus}, aperture: {ap}, robust: {robust}}})")
        assert info["workers"] == 0 and np.array_equal(canvas_rgb(page), got["&workers=0", 0][0])
    finally:
        page.unroute("**/render_worker.js")


@pytest.mark.parametrize("name", ["dino.lfc", "res.lfc"])
def test_the_blend_on_webassembly_draws_the_loops_canvas(site, page, name):
    """The novel-view blend and the views' prediction on WebAssembly SIMD (render_kernel.wat,
    predict_kernel.wat: the default where the browser has it) draw the canvas of render.js's and
    lfc.js's loops (&wasm=0), bit for bit, robust, refocused, synthetic-aperture and as a bilinear
    preview; the stats line says which ran."""
    srv, _ = site
    got = {}
    for query in ("&workers=0", "&workers=0&wasm=0"):
        assert open_viewer(page, srv, name, query) == "ready", page.inner_text("#error")
        for i, (canvas, _) in enumerate(show_cams(page)):
            got[query, i] = canvas
        stats = page.inner_text("#stats")
        assert ("JS loops" if "wasm=0" in query else "WebAssembly SIMD") in stats.split("frame ")[-1]
        assert ("predicted in JS loops" if "wasm=0" in query else "predicted on WebAssembly SIMD") in stats
        got[query, "preview"] = preview_pixels(page)
    for k in list(range(len(CAMS))) + ["preview"]:
        assert np.array_equal(got["&workers=0", k], got["&workers=0&wasm=0", k]), k


def test_a_viewer_module_that_cannot_load_shows_a_message(site, page):
    """A module the page imports that cannot be fetched fails the page at once with a message
    (before, the page stayed "loading" with nothing said)."""
    srv, _ = site
    page.route("**/render_kernel.js", lambda route: route.abort())
    try:
        page.goto(srv.viewer_url("dino.lfc"))
        page.wait_for_function("document.body.dataset.state !== 'loading'", timeout=30_000)
        assert page.evaluate("document.body.dataset.state") == "error"
        assert "could not be loaded" in page.inner_text("#error")
    finally:
        page.unroute("**/render_kernel.js")


def test_a_grid_whose_every_view_is_alone_renders_through_its_shared_map(site, page):
    """Every view a JPEG 2000 image, no view predicted through a map: the page shows the views
    (OpenJPEG's wasm against imagecodecs: within 1) and renders novel views through the file's
    shared map (here 1 px per view step everywhere): the same frame as that disparity given as
    the focus, not the unshifted blend it drew when it looked for a view with a map and found
    none; the frames are the Python renderer's (bicubic in both since stop 84: this grid's
    noise-like texture is where bilinear and bicubic blends differ most)."""
    srv, f = site
    assert open_viewer(page, srv, "alone.lfc") == "ready", page.inner_text("#error")
    d = open_decoder(open_lfc(f.parent / "alone.lfc"))
    assert (d.core.lay.cell < 0).all() and len(d.core.img_of) == d.rows * d.cols
    assert (d.core.cell_map(0) == 16).all()
    page.evaluate("lfcViewer.show(2, 3)")
    assert np.abs(canvas_rgb(page).astype(int) - d.decode_view(2, 3)).max() <= 1
    r = d.renderer()
    for s, t in ((1.4, 2.7), (2.5, 1.5)):
        frames = []
        for focus in ("null", "1.0", "0.0"):
            page.evaluate(f"lfcViewer.show({s}, {t}, {{focus: {focus}, aperture: 0}})")
            frames.append(canvas_rgb(page).astype(int))
        assert (frames[0] == frames[1]).all() and np.abs(frames[0] - frames[2]).max() > 8
        assert (r.render(s, t) == r.render(s, t, 1.0)).all()          # (the Python renderer: the same rule)
        # (every view here is a JPEG 2000 image, where OpenJPEG's wasm and imagecodecs differ by 1
        # at a few samples; the blends carry those)
        assert_same_frame(r.render(s, t), frames[0], share=0.01)
        assert_same_frame(r.render(s, t, 0.0), frames[2], share=0.01)


def test_drag_moves_the_viewpoint(site, page):
    """A drag moves the camera (bilinear previews on the way); once it rests, the frame is the
    Python renderer's at the new camera."""
    srv, f = site
    assert open_viewer(page, srv, f.name) == "ready"
    before = page.evaluate("[lfcViewer.state.s, lfcViewer.state.t]")
    drag(page)
    page.wait_for_function("!lfcViewer.state.busy && lfcViewer.state.last.cubic")
    after = page.evaluate("[lfcViewer.state.s, lfcViewer.state.t]")
    assert after[0] > before[0] and after[1] > before[1]
    r = open_decoder(open_lfc(f)).renderer()
    assert_same_frame(r.render(*after), canvas_rgb(page))
    assert "bilinear preview" not in page.inner_text("#stats")


@pytest.mark.parametrize("name, words", [("corrupt.lfc", "checksum"), ("cut.lfc", "truncated"),
                                         ("missing.lfc", "HTTP 404"), ("secret.txt", "not an .lfc")])
def test_bad_files_show_a_message(site, page, name, words):
    """A damaged file shows its error on the page. Key views are decoded when a frame first needs
    them (stop 85), so a damaged chunk that the first frame does not read is reported when a
    later frame reads it (corrupt.lfc: its last chunk): every captured view is shown in turn, and
    the error shows on the page (a script's show() gets it too)."""
    srv, _ = site
    state = open_viewer(page, srv, name)
    if state == "ready" and name == "corrupt.lfc":
        page.evaluate("""async () => { const d = lfcViewer.decoder;
            for (let r = 0; r < d.rows; r++) for (let c = 0; c < d.cols; c++) {
              try { await lfcViewer.show(r, c); } catch { return; } } }""")
        state = page.evaluate("document.body.dataset.state")
    assert state == "error"
    msg = page.inner_text("#error")
    assert words in msg and name in msg
    assert page.locator("#error").is_visible()


def test_server_confines_paths(site):
    import urllib.error
    import urllib.request

    srv, _ = site
    base = f"http://{srv.host}:{srv.port}/"
    for path in ("../../etc/passwd", "_viewer/../../../etc/passwd", "_viewer/package.json", "%2e%2e/%2e%2e/etc/hosts",
                 "_viewer/node_modules/x"):
        with pytest.raises(urllib.error.HTTPError) as e:
            urllib.request.urlopen(base + path)
        assert e.value.code == 404, path
    with urllib.request.urlopen(base + "_viewer/lfc.js") as r:
        assert r.headers["Content-Type"].startswith("text/javascript")


def canvas_rgba(page) -> np.ndarray:
    w, h, data = page.evaluate("""() => { const c = document.getElementById('view');
        const d = c.getContext('2d').getImageData(0, 0, c.width, c.height);
        return [c.width, c.height, Array.from(d.data)]; }""")
    return np.asarray(data, np.uint8).reshape(h, w, 4)


def test_light_field_networks_render_in_the_page(site, page):
    from lfn_stream import LfnRenderer

    srv, f = site
    net = f.parent / "net_posed.lfc"
    assert open_viewer(page, srv, net.name) == "ready", page.inner_text("#error")
    assert page.evaluate("lfcViewer.state.mode") == "lfn" and "neurons" in page.inner_text("#stats")
    r = LfnRenderer(open_lfc(net), device="cpu")
    for cam, pose, neurons, scale in (("{view: 2}", r.pose(0, 2), 20, 1), ("{view: 4, yaw: 25, pitch: -10}",
                                      r.orbit_pose(0, 4, 25, -10), 13.5, 1), ("{view: 1}", r.pose(0, 1), 9.25, "'auto'")):
        info = page.evaluate(f"lfcViewer.show({cam}, {{neurons: {neurons}, scale: {scale}}})")
        np.testing.assert_allclose(np.array(info["pose"]).reshape(4, 4), pose, atol=1e-12)
        want = r.to_pixels(r.render_pose(pose, float(neurons), None if scale == "'auto'" else 1.0))
        got = canvas_rgba(page)[..., :3]
        assert got.shape == want.shape
        assert np.abs(got.astype(int) - want).max() <= 1 and (got != want).mean() < 0.02


def test_networks_trained_below_the_views_size_render_on_their_own_grid(site, page):
    """A network whose display ladders say it was trained at 1/4 of the views' size: the page
    renders it on a lattice every 4 pixels by default (LfnRenderer.render_pose(..., native=True)'s
    pixels, and the stats say so), and densely with the box unticked."""
    from lfn_stream import LfnRenderer

    srv, f = site
    net = f.parent / "net_native.lfc"
    assert open_viewer(page, srv, net.name) == "ready", page.inner_text("#error")
    r = LfnRenderer(open_lfc(net), device="cpu")
    pose = r.orbit_pose(0, 3, 20, -5)
    for native, opt in ((True, ""), (False, ", native: false")):        # the default, then unticked
        info = page.evaluate(f"lfcViewer.show({{view: 3, yaw: 20, pitch: -5}}, {{neurons: 20, scale: 1{opt}}})")
        assert info["stride"] == (4 if native else 1)
        assert ("every 4 pixels" in page.inner_text("#stats")) == native
        assert page.evaluate("document.getElementById('native').checked") == native
        want = r.to_pixels(r.render_pose(pose, 20.0, 1.0, native=native))
        got = canvas_rgba(page)[..., :3]
        assert got.shape == want.shape
        assert np.abs(got.astype(int) - want).max() <= 1 and (got != want).mean() < 0.02
        empty = (want == 0).all(-1).mean()                       # the occupancy net cut part of the frame
        assert 0.01 < empty < 0.99, empty


def test_foveated_frames_follow_the_pointer(site, page):
    """"foveate" draws LfnRenderer.render_pose_lod_mip's frame (within one grey level; densely and
    on the network's own grid), the same canvas on workers as on the page's thread, with fewer
    network passes than the full frame; the gaze follows the pointer over the canvas."""
    from lfn_stream import LfnRenderer

    srv, f = site
    net = f.parent / "net_native.lfc"
    r = LfnRenderer(open_lfc(net), device="cpu")
    pose = r.orbit_pose(0, 3, 20, -5)
    cam = "{view: 3, yaw: 20, pitch: -5}"
    got = {}
    for query in ("", "&workers=0"):
        assert open_viewer(page, srv, net.name, query) == "ready", page.inner_text("#error")
        full = page.evaluate(f"lfcViewer.show({cam}, {{neurons: 20, scale: 2, native: false}})")
        for native in (False, True):
            info = page.evaluate(f"lfcViewer.show({cam}, {{scale: 2, native: {str(native).lower()}, fovea: true, "
                                 "gaze: [0.3, 0.6]})")
            assert info["levels"] >= 3 and info["evaluated"] < full["evaluated"], info
            assert info["gaze"] == [0.3 * 60, 0.6 * 48] and "foveated" in page.inner_text("#stats")
            want = r.to_pixels(r.render_pose_lod_mip(pose, r.foveation_map((18, 28.8), dither=False, scale=2.0),
                                                     native=native))
            px = canvas_rgba(page)
            assert np.abs(px[..., :3].astype(int) - want).max() <= 1 and (px[..., :3] != want).mean() < 0.02
            got[query, native] = px
    for native in (False, True):
        assert np.array_equal(got["", native], got["&workers=0", native])
    # the pointer: the gaze follows it (a fraction of the frame, shown in frame pixels)
    page.evaluate(f"lfcViewer.show({cam}, {{scale: 2, native: false, fovea: true, gaze: [0.5, 0.5]}})")
    assert page.evaluate("document.getElementById('fovea').checked")
    box = page.locator("#view").bounding_box()
    page.mouse.move(box["x"] + 0.25 * box["width"], box["y"] + 0.75 * box["height"])
    page.wait_for_function("lfcViewer.state.last.gaze && Math.abs(lfcViewer.state.last.gaze[0] - 15) < 1.5")
    assert abs(page.evaluate("lfcViewer.state.last.gaze[1]") - 36) < 1.5


@pytest.mark.parametrize("native", [True, False])
def test_network_passes_on_workers_give_the_page_threads_pixels(site, page, native):
    """The page runs the networks' passes on Web Workers (two here: the cores Chromium reports)
    and their layers on WebAssembly: the canvas is the same, byte for byte, as with &workers=0
    (every pass on the page's thread) and with &wasm=0 (lfn.js's own loops, in the workers too),
    with and without the native lattice and while the network grows."""
    srv, f = site
    cams = ["{view: 3, yaw: 20, pitch: -5}, {neurons: 20, scale: 1", "{view: 1}, {neurons: 9.25, scale: 'auto'"]
    got = {}
    for query in ("", "&workers=0", "&wasm=0"):
        assert open_viewer(page, srv, "net_native.lfc", query + "&neurons=8") == "ready", page.inner_text("#error")
        for i, cam in enumerate(cams):
            info = page.evaluate(f"lfcViewer.show({cam}, native: {str(native).lower()}}})")
            got[query, i] = (canvas_rgba(page), info["workers"], info["evaluated"])
            assert info["wasm"] == (query != "&wasm=0")          # the kernel compiled in the page (< 4 KB)
        if not query:
            assert "worker" in page.inner_text("#stats")
    for i in range(len(cams)):
        assert got["", i][1] >= 1 and got["&workers=0", i][1] == 0 and got["&wasm=0", i][1] >= 1
        assert got["", i][0][..., :3].std() > 10                # a picture, not a blank canvas
        for q in ("&workers=0", "&wasm=0"):
            assert np.array_equal(got["", i][0], got[q, i][0]) and got["", i][2] == got[q, i][2], q


def test_workers_that_cannot_start_leave_the_frame_to_the_page(site, page):
    """A page whose worker script cannot load (blocked here) draws on its own thread: the same
    canvas as &workers=0, and the frame says no workers ran it."""
    srv, f = site
    cam = "lfcViewer.show({view: 3, yaw: 20, pitch: -5}, {neurons: 20, scale: 1})"
    assert open_viewer(page, srv, "net_native.lfc", "&workers=0") == "ready", page.inner_text("#error")
    page.evaluate(cam)
    want = canvas_rgba(page)
    page.route("**/lfn_worker.js", lambda route: route.abort())
    try:
        assert open_viewer(page, srv, "net_native.lfc") == "ready", page.inner_text("#error")
        info = page.evaluate(cam)
        assert info["workers"] == 0 and np.array_equal(canvas_rgba(page), want)
        assert "page's thread" in page.inner_text("#stats")
    finally:
        page.unroute("**/lfn_worker.js")


def test_network_weights_stream_as_the_level_rises(site, page):
    srv, f = site
    net = f.parent / "net_grid.lfc"
    page.goto(srv.viewer_url(net.name) + "&neurons=8")
    page.wait_for_function("document.body.dataset.state !== 'loading'", timeout=120_000)
    assert page.evaluate("document.body.dataset.state") == "ready", page.inner_text("#error")
    low = page.evaluate("lfcViewer.show({s: 1.3, t: 2.6}, {neurons: 8})")
    high = page.evaluate("lfcViewer.show({s: 1.3, t: 2.6}, {neurons: 20})")
    assert low["neuronsFetched"] == 8 and high["neuronsFetched"] == 20
    assert low["bytesFetched"] < high["bytesFetched"] <= net.stat().st_size
    assert 0 < high["requests"] - low["requests"] <= 2          # one range request for all the new steps
    before = page.evaluate("[lfcViewer.state.s, lfcViewer.state.t]")
    drag(page)
    after = page.evaluate("[lfcViewer.state.s, lfcViewer.state.t]")
    assert after != before


def test_tile_sets_render_in_the_page(site, page):
    """A tile set's manifest opens like one network: only the tiles a camera blends are opened, and
    the frame is the Python TiledLfnRenderer's blend within one grey level."""
    from lfn_stream import open_tiles

    srv, f = site
    assert open_viewer(page, srv, "set.json") == "ready", page.inner_text("#error")
    assert page.evaluate("lfcViewer.state.mode") == "lfn" and "tiles" in page.inner_text("#stats")
    assert page.evaluate("lfcViewer.decoder.tiles.size") == 1           # camera 0 is tile 0's centre
    t = open_tiles(f.parent / "set.json", device="cpu")
    for cam, pose, neurons, tiles in (("{view: 1}", t.pose(0, 1), 20, [0, 1]), ("{view: 1, yaw: -10, pitch: 5}",
                                      t.orbit_pose(0, 1, -10, 5), 12.5, [0, 1]), ("{view: 3}", t.pose(0, 3), 14, [1])):
        info = page.evaluate(f"lfcViewer.show({cam}, {{neurons: {neurons}, scale: 1}})")
        assert sorted(info["tiles"]) == sorted(t.weights(pose)) == tiles, (info["tiles"], t.weights(pose), cam)
        want = t.to_pixels(t.render_pose(pose, float(neurons), 1.0))
        got = canvas_rgba(page)[..., :3]
        assert got.shape == want.shape
        assert np.abs(got.astype(int) - want).max() <= 1 and (got != want).mean() < 0.02
    assert page.evaluate("lfcViewer.decoder.tiles.size") == 2
    # foveated: the blend of the tiles' foveated frames (TiledLfnRenderer.render_pose_lod_mip)
    info = page.evaluate("lfcViewer.show({view: 1}, {neurons: 20, scale: 1, fovea: true, gaze: [0.4, 0.5]})")
    assert sorted(info["tiles"]) == [0, 1] and info["levels"] >= 2
    want = t.to_pixels(t.render_pose_lod_mip(t.pose(0, 1), t.foveation_map(tuple(info["gaze"]), dither=False)))
    got = canvas_rgba(page)[..., :3]
    assert np.abs(got.astype(int) - want).max() <= 1 and (got != want).mean() < 0.02
    sizes = sum((f.parent / n).stat().st_size for n in ("set.json", "set.tile00.lfc", "set.tile01.lfc"))
    assert 2 < info["requests"] and info["bytesFetched"] <= sizes
    t.close()


@pytest.mark.parametrize("name, words", [("escape.json", "relative name"), ("mixed.json", "differ from the others")])
def test_bad_tile_sets_show_a_message(site, page, name, words):
    srv, _ = site
    state = open_viewer(page, srv, name)
    if name == "mixed.json":                       # tile 1 is opened when a camera first blends it
        assert state == "ready"
        with pytest.raises(Exception, match=words):
            page.evaluate("lfcViewer.show({view: 1}, {neurons: 8})")
        return
    assert state == "error"
    assert words in page.inner_text("#error") and name in page.inner_text("#error")
