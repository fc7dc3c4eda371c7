"""The browser viewer's LFN renderer (formats/web/lfn.js under Node) against the Python
renderer (``LfnRenderer`` on the CPU, torch with one thread) on the same file: time per frame
of captured view 0 at several network sizes (each at its own scale, and the full network at
full scale, densely and on the network's own pixel grid: ``native``), weight bytes the viewer
had fetched for that size, and pixel agreement.

    python -m tools.bench_web_lfn FILE.lfc [--rounds 3]

Prints a Markdown table (ratios JS / Python; this box is noisy, read the ratios): the JS times
with lfn.js's own loops and with its WebAssembly layers (the pixels compared are the latter's;
the two are byte-identical, tests/formats/test_web_lfn.py).

``--page``: instead, the viewer page itself in headless Chromium (``LFC_CHROMIUM`` or Debian's
``chromium``, driven by Playwright) over ``lfcodec serve``'s server: the full network's frame of
captured view 0 at full scale, densely and on the network's own pixel grid, with its passes on
the page's thread (``&workers=0``) and on Web Workers (the page's default: as many as the cores
Chromium reports, at most 8), in lfn.js's own loops (``&wasm=0``) and on its WebAssembly layers,
settings interleaved round by round; medians. ``--page --fovea``: also foveated frames (gaze at
the centre: the viewer's "foveate" box, ``renderMip``) on the WebAssembly layers."""
from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("file")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--page", action="store_true", help="time the viewer page in headless Chromium instead")
    ap.add_argument("--fovea", action="store_true", help="--page: foveated frames too")
    a = ap.parse_args(argv)
    if a.page:
        return page_bench(Path(a.file).resolve(), a.rounds, a.fovea)
    node = shutil.which("node")
    if node is None:
        print("Node.js is not installed", file=sys.stderr)
        return 2
    import torch

    from formats import open_lfc
    from lfn_stream import LfnRenderer

    torch.set_num_threads(1)
    r = LfnRenderer(open_lfc(a.file), device="cpu")
    lo, hi = r.cfg.min_neurons, r.cfg.max_neurons
    sizes = sorted({lo, round(lo + (hi - lo) / 4), round(lo + (hi - lo) / 2), hi})
    settings = [(n, "auto", False) for n in sizes] + [(hi, "1", False), (hi, "1", True)]
    with tempfile.TemporaryDirectory() as tmp:
        import os

        def node_run(wasm: bool) -> list:
            env = dict(os.environ, **({} if wasm else {"LFN_NO_WASM": "1"}))
            got = subprocess.run([node, str(ROOT / "tools" / "web_lfn_bench.mjs"), a.file, tmp, str(a.rounds),
                                  *[f"{n},{s}" + (",native" if nat else "") for n, s, nat in settings]],
                                 capture_output=True, text=True, check=True, env=env)
            return json.loads(got.stdout.strip().splitlines()[-1])

        loops = node_run(False)              # lfn.js's own loops, then the WebAssembly layers (whose pixels stay)
        js = node_run(True)
        print(f"{Path(a.file).name}: depth {r.cfg.depth}, {lo}..{hi} neurons, views {r.width}x{r.height}, "
              f"{'occupancy net' if r.occ is not None else 'no occupancy net'}\n")
        print("| neurons | scale | sampled | frame | weights fetched | JS loops ms | JS + wasm ms | Python ms | JS+wasm/Python | max diff | pixels differing |")
        print("|---|---|---|---|---|---|---|---|---|---|---|")
        for i, ((n, s, nat), j, lo) in enumerate(zip(settings, js, loops)):
            times = []
            for _ in range(a.rounds):
                t = time.perf_counter()
                out = r.render_pose(r.pose(0, 0), float(n), None if s == "auto" else float(s), native=nat)
                times.append(1e3 * (time.perf_counter() - t))
            want = r.to_pixels(out)
            px = np.fromfile(Path(tmp) / f"px_{i}.bin", want.dtype).reshape(want.shape)
            d = np.abs(px.astype(np.int64) - want)
            py = float(np.median(times))
            print(f"| {n} | {'own' if s == 'auto' else s} ({r.cfg.scale_of(n) if s == 'auto' else 1:.3f}) | "
                  f"{'every ' + str(j['stride']) + ' px' if j['stride'] > 1 else 'every pixel'} | {j['w']}x{j['h']} | {j['bytes'] / 1024:.1f} KiB | {lo['ms']:.0f} | {j['ms']:.0f} | {py:.0f} | {j['ms'] / py:.1f}x | "
                  f"{int(d.max())} | {(d > 0).mean() * 100:.4f}% |")
    return 0


def page_bench(path: Path, rounds: int, fovea: bool = False) -> int:
    """``--page``: frame times of the viewer page (see the module docstring)."""
    import os

    from playwright.sync_api import sync_playwright

    from formats.serve import FileServer

    chromium = os.environ.get("LFC_CHROMIUM") or shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        print("Chromium is not installed", file=sys.stderr)
        return 2
    flags = ["--no-sandbox", "--disable-gpu", "--no-first-run", "--disable-background-networking"]
    settings = [(w + q, nat, False) for w in ("&wasm=0", "") for q in ("&workers=0", "") for nat in (False, True)]
    if fovea:
        settings += [(q, nat, True) for q in ("&workers=0", "") for nat in (False, True)]
    times: dict = {k: [] for k in settings}
    info: dict = {}
    with FileServer(path.parent, viewer=True) as srv, sync_playwright() as p:
        browser = p.chromium.launch(executable_path=chromium, headless=True, args=flags)
        page = browser.new_page()
        for _ in range(rounds):
            for q, nat, fov in settings:
                page.goto(srv.viewer_url(path.name) + q)
                page.wait_for_function("document.body.dataset.state !== 'loading'", timeout=600_000)
                cam = f"lfcViewer.show({{view: 0}}, {{scale: 1, native: {str(nat).lower()}, fovea: {str(fov).lower()}}})"
                page.evaluate(cam)                                   # (the first frame: the pool's start-up)
                got = page.evaluate(cam)
                times[q, nat, fov].append(got["ms"])
                info[q, nat, fov] = got
        cores = page.evaluate("navigator.hardwareConcurrency")
        browser.close()
    print(f"{path.name}: the viewer page in headless Chromium ({cores} cores reported), view 0, full network, "
          f"medians of {rounds}\n")
    print("| network | passes on | sampled | foveated | frame | rays run | frame ms |")
    print("|---|---|---|---|---|---|---|")
    for key in settings:
        q, nat, fov = key
        g = info[key]
        where = "the page's thread" if "workers=0" in q else f"{g['workers']} workers"
        print(f"| {'JS loops' if 'wasm=0' in q else 'WebAssembly'} | {where} | "
              f"{('own grid, every ' + str(g['stride']) + ' px') if nat and g['stride'] > 1 else 'every pixel'} | "
              f"{str(g['levels']) + ' levels' if fov else 'no'} | "
              f"{g['w']}x{g['h']} | {g['evaluated']} | {float(np.median(times[key])):.0f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
