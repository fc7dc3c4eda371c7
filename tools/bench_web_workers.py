"""The browser viewer's novel-view frames with the blend on Web Workers (render_pool.js) against
the page's own thread, in headless Chromium (Debian's ``chromium`` via Playwright), the two
settings alternated per round on the same files.

    python -m tools.bench_web_workers FILE.lfc [FILE.lfc ...] [--rounds 3] [--workers 2[,3...]]
    python -m tools.bench_web_workers FILE.lfc ... --settings "workers=0&wasm=0,workers=0,workers=2"

Per file: the viewer opened with ``&workers=0`` and with each ``&workers=N`` (the page's thread
and N − 1 workers share the blend), or with each of ``--settings`` (URL query parameters, the
first the baseline: e.g. ``wasm=0``, the blend in render.js's loops); each round renders 8
cameras twice (robust, bicubic; the first pass warms the views' decode and the JIT up and is
left out) and takes the frame times the renderer reports. Paths: ``jump`` (default), the 8 cameras of
``tools.bench_web``'s path, which cross a row or column of views between most frames (new
source views to send); ``drag``, 8 cameras 0.02 view steps apart inside one cell, as a drag
moves the camera between frames. Prints a Markdown table of medians (ms) and the ratios to the
page's thread alone, and checks that every setting draws the same canvas."""
from __future__ import annotations

import argparse
import os
import shutil
import statistics
import sys
import tempfile
from pathlib import Path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("files", nargs="+")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--workers", default="2", help="comma-separated settings of &workers (each > 0)")
    ap.add_argument("--settings", default=None,
                    help="comma-separated URL query settings, the first the baseline (instead of --workers)")
    ap.add_argument("--path", choices=("jump", "drag"), default="jump")
    a = ap.parse_args(argv)
    chromium = os.environ.get("LFC_CHROMIUM") or shutil.which("chromium") or shutil.which("chromium-browser")
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        sync_playwright = None
    if chromium is None or sync_playwright is None:
        print("needs Chromium and Playwright (apt-get install chromium; pip install playwright)", file=sys.stderr)
        return 2
    from formats.serve import FileServer

    if a.settings:
        base, *settings = a.settings.split(",")
    else:
        base, settings = "workers=0", [f"workers={int(x)}" for x in a.workers.split(",")]
    print(f"| file ({a.path}) | &{base} ms | " + " | ".join(f"&{n} ms (ratio)" for n in settings) + " | same canvas |")
    print("|---|---|" + "---|" * len(settings) + "---|")
    with tempfile.TemporaryDirectory() as tmp, sync_playwright() as p:
        browser = p.chromium.launch(executable_path=chromium, headless=True, args=["--no-sandbox", "--disable-gpu"])
        page = browser.new_page()
        for f in (Path(x).resolve() for x in a.files):
            shutil.copyfile(f, Path(tmp) / f.name)      # (the server serves no links out of its folder)
        with FileServer(tmp, viewer=True) as srv:
            for f in (Path(x) for x in a.files):
                times = {n: [] for n in [base] + settings}
                frames = {}
                for _ in range(a.rounds):
                    for n in times:
                        page.goto(srv.viewer_url(f.name) + f"&{n}")
                        page.wait_for_function("document.body.dataset.state !== 'loading'", timeout=300_000)
                        if page.evaluate("document.body.dataset.state") != "ready":
                            print(f"{f.name}: {page.inner_text('#error')}", file=sys.stderr)
                            return 1
                        ms = page.evaluate("""async (drag) => { const d = lfcViewer.decoder, out = [];
                            for (let i = 0; i < 16; i++) {                  // (the first 8: warm-up)
                              const k = i % 8;
                              const s = drag ? Math.floor((d.rows - 1) / 2) + 0.35 + 0.02 * k : (d.rows - 1) * (0.3 + 0.05 * k);
                              const t = drag ? Math.floor((d.cols - 1) / 2) + 0.6 - 0.02 * k : (d.cols - 1) * (0.6 - 0.04 * k);
                              out.push((await lfcViewer.show(s, t)).ms); }
                            return out; }""", a.path == "drag")
                        times[n] += ms[8:]
                        frames[n] = page.evaluate("""() => { const c = document.getElementById('view');
                            return Array.from(c.getContext('2d').getImageData(0, 0, c.width, c.height).data); }""")
                m = {n: statistics.median(v) for n, v in times.items()}
                cells = " | ".join(f"{m[n]:.0f} ({m[n] / m[base]:.2f})" for n in settings)
                same = all(frames[n] == frames[base] for n in settings)
                print(f"| {f.stem} | {m[base]:.0f} | {cells} | {same} |", flush=True)
        browser.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
