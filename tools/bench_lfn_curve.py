"""LFN quality against bytes: does the picture improve as the stream arrives?

For an LFN file and the scene it was trained on, renders the held-out views (``config.train.
test_views``, less the ``display_views`` the encoder measured its display ladder on) at one display scale with every integer network size the stream holds
(min_neurons … max_neurons; one size per step of the file), and scores each against the
area-downsampled views (premultiplied RGBA on black, as :mod:`lfn_stream.evaluate`). Two curves:

- ``raw``: a renderer that shows every size it holds (what a reader without a display ladder
  shows, and what ``--level`` asks for);
- ``display``: a renderer at that scale that shows :meth:`LfnRenderer.display_neurons_at` for the
  bytes held (the largest size those bytes reach of the file's ladder for the nearest display
  scale, ``config.display_scales``, else of ``config.display``).

Reports, per curve, how many steps lower the held-out PSNR by more than 0.1 dB (issue 17: none),
the worst drop, the mean PSNR over the steps, and the bytes of the first and the last prefix.

Usage:
    python -m tools.bench_lfn_curve FILE.lfc SCENE [--scale 0.5] [--views 10] [--out JSON]
"""
from __future__ import annotations

import argparse
import math

import numpy as np
import torch

from formats.lfcfile import open_lfc
from lfn_stream import LfnRenderer
from lfn_stream.evaluate import prefix_bytes
from lfn_stream.sat import area_downsample
from lfn_stream.training import targets_of
from tools.common import log, machine, write_json


def curve(r: LfnRenderer, lf, views, scale: float) -> np.ndarray:
    """Held-out PSNR (dB) of every integer size on ``views`` at ``scale``: (sizes,) float64."""
    peak = float(np.iinfo(lf.views.dtype).max)
    flat = lf.views.reshape(-1, lf.height, lf.width, lf.channels)
    nch = 4 if lf.has_alpha else 3
    refs = {v: area_downsample(targets_of(flat[v][None], lf.has_alpha)[0].astype(np.float32) / peak,
                               scale)[..., :nch] for v in views}
    out = []
    for w in range(r.cfg.min_neurons, r.cfg.max_neurons + 1):
        mse = [np.mean((r.render(v // lf.cols, v % lf.cols, float(w), scale)[..., :nch] - refs[v]) ** 2) for v in views]
        out.append(10 * math.log10(1 / float(np.mean(mse))))
    return np.asarray(out)


def displayed(psnr: np.ndarray, ladder: list[int] | None, lo: int) -> np.ndarray:
    """The PSNR shown after each step: each size's own, or that of the largest ladder size ≤ it."""
    if not ladder:
        return psnr.copy()
    idx = [max(w for w in ladder if w <= lo + i) - lo for i in range(len(psnr))]
    return psnr[idx]


def summary(p: np.ndarray) -> dict:
    d = np.diff(p)
    return {"drops_over_0.1dB": int((d < -0.1).sum()), "worst_drop_db": round(float(d.min()), 3),
            "mean_psnr": round(float(p.mean()), 3), "first_psnr": round(float(p[0]), 3),
            "last_psnr": round(float(p[-1]), 3)}


def open_with_scene(file: str, scene: str, test_scene: str | None, device: str):
    """(LfnRenderer of ``file`` on ``device``, the light field it was trained on at the file's
    resolution, the separate test split's views appended when given)."""
    from tools.bench_lfn import load, with_test_views

    r = LfnRenderer(open_lfc(file), device=device)
    lf = load(scene, max(r.height, r.width))
    if test_scene:
        lf = with_test_views(lf, load(test_scene, max(r.height, r.width), split="test"))
    if (lf.height, lf.width) != (r.height, r.width):
        raise SystemExit(f"{scene}: views are {lf.height}x{lf.width}, the file's {r.height}x{r.width}")
    return r, lf


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("file")
    ap.add_argument("scene", help="the scene folder the network was trained on (or a .npz of tools.bench_lfn)")
    ap.add_argument("--scale", type=float, default=0.5, help="display scale relative to the views (default 0.5)")
    ap.add_argument("--views", type=int, default=10, help="held-out views scored (default 10, the first ones)")
    ap.add_argument("--test-scene", default=None,
                    help="the separate test split the file's held-out views come from (tools.bench_lfn --test-scene)")
    ap.add_argument("--device", default="cpu", help="torch device the network runs on (cpu, cuda)")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", default=None, help="write the results as JSON")
    a = ap.parse_args(argv)
    torch.set_num_threads(a.threads)
    r, lf = open_with_scene(a.file, a.scene, a.test_scene, a.device)
    tr = r.file.full_meta()["config"]["train"]
    used = set(tr.get("display_views", []))          # views the encoder measured the ladder on: not scored
    views = [v for v in tr["test_views"] if v not in used][:a.views]
    log(f"{a.file}: {len(views)} held-out views at scale {a.scale}, sizes {r.cfg.min_neurons}..{r.cfg.max_neurons}")
    raw = curve(r, lf, views, a.scale)
    lo = r.cfg.min_neurons
    ladder = r.display_ladder_at(a.scale)      # the one a renderer at this scale uses
    shown = displayed(raw, ladder, lo)
    res = {"file": a.file, "scene": a.scene, "scale": a.scale, "views": views, "machine": machine(),
           "display_ladder": ladder, "bytes": [prefix_bytes(r, float(w)) for w in range(lo, r.cfg.max_neurons + 1)],
           "psnr_raw": raw.round(4).tolist(), "psnr_display": shown.round(4).tolist(),
           "raw": summary(raw), "display": summary(shown)}
    print("| curve | steps dropping > 0.1 dB | worst drop | mean PSNR | first → last |\n|---|---|---|---|---|")
    for k in ("raw", "display"):
        s = res[k]
        print(f"| {k} | {s['drops_over_0.1dB']} of {len(raw) - 1} | {s['worst_drop_db']:.2f} dB | "
              f"{s['mean_psnr']:.2f} | {s['first_psnr']:.2f} → {s['last_psnr']:.2f} |")
    write_json(a.out, res)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
