"""`lfcodec view IN.lfc`: starts a local server, prints the viewer's URL; the page, its scripts
(JavaScript MIME type, as module scripts require), the WebAssembly decoder and the file by byte
ranges are all served from it."""
from __future__ import annotations

import subprocess
import sys
import urllib.request
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
GOLDEN = ROOT / "tests" / "data" / "golden" / "rlfc_tx2_lossy_rgb8.lfc"


def test_view_prints_a_working_url(tmp_path):
    f = tmp_path / "lf.lfc"
    f.write_bytes(GOLDEN.read_bytes())
    p = subprocess.Popen([sys.executable, "-m", "formats.cli", "view", str(f), "--port", "0"], stdout=subprocess.PIPE,
                         text=True, cwd=ROOT)
    try:
        line = p.stdout.readline()
        url = line.split(": ", 1)[1].strip()
        assert url.startswith("http://127.0.0.1:") and url.endswith("/_viewer/index.html?file=/lf.lfc"), line
        base = url.split("/_viewer/")[0]
        with urllib.request.urlopen(url) as r:
            assert b"viewer.js" in r.read() and r.headers["Content-Type"].startswith("text/html")
        for name, kind in (("viewer.js", "text/javascript"), ("lfc.js", "text/javascript"),
                           ("vendor/openjpegwasm_decode.wasm", "application/wasm")):
            with urllib.request.urlopen(f"{base}/_viewer/{name}") as r:
                assert r.headers["Content-Type"].startswith(kind) and len(r.read()) > 1000
        req = urllib.request.Request(f"{base}/lf.lfc", headers={"Range": "bytes=0-31"})
        with urllib.request.urlopen(req) as r:
            assert r.status == 206 and r.read()[:4] == b"\x89LFC"
    finally:
        p.terminate()
        p.wait(10)


def test_viewer_url_of_names_with_url_characters(tmp_path):
    # the page resolves its `file` parameter as a URL (as below, like the browser's new URL()):
    # a raw '#' or '?' in a file name started a fragment or a query and the page fetched another path
    from urllib.parse import parse_qs, urljoin, urlparse

    from formats.serve import FileServer

    names = ["lf.lfc", "a b é#?.lfc", "100%.lfc", "x&y=1+2.lfc"]
    for n in names:
        (tmp_path / n).write_bytes(GOLDEN.read_bytes())
    with FileServer(tmp_path, viewer=True) as srv:
        assert srv.viewer_url("lf.lfc").endswith("/_viewer/index.html?file=/lf.lfc")     # plain names unchanged
        for n in names:
            page = srv.viewer_url(n)
            value = parse_qs(urlparse(page).query)["file"][0]                    # URLSearchParams.get
            with urllib.request.urlopen(urljoin(page, value)) as r:              # new URL(value, page)
                assert r.read() == GOLDEN.read_bytes(), n


def test_the_server_hands_out_every_file_the_viewer_imports():
    """Every module the viewer's scripts import (``from "./X.js"``, ``new URL("./X.js", …)``,
    ``import("./X.js")``) is one of the files `lfcodec serve` hands out, starting from the page's
    own scripts: a module left off the list fails the page's load in the browser (a new kernel
    did once, stop 85)."""
    import re

    from formats.serve import _WEB_FILES, WEB_DIR

    seen, todo = set(), re.findall(r'src="(?:\./)?([^"]+\.js)"', (WEB_DIR / "index.html").read_text())
    assert todo, "index.html names no script"
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        seen.add(name)
        assert name in _WEB_FILES, f"{name} is imported by the viewer but not served"
        text = (WEB_DIR / name).read_text()
        for ref in re.findall(r'(?:from|import\(|new URL\()\s*"\./([^"]+\.js)"', text):
            todo.append(str(Path(name).parent / ref) if "/" in name else ref)
    assert {"render_kernel.js", "lfn_kernel.js", "render_worker.js", "lfn_worker.js"} <= seen
