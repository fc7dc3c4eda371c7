"""Dense grids the codec was not tuned on: RLFC against per-view JPEG 2000 at a target PSNR.

Usage: ``python -m tools.unseen DATA_DIR --out DIR [--target 40] [--profile tx] [--save-scenes]``

The grids are derived deterministically from ../shared/data:

- ``antinous_noise3``: hci_antinous with Gaussian noise σ = 3 grey levels added to every view
  (independent per view, seed 0): render/sensor noise above a 40 dB target's error.
- ``antinous_vignette``: hci_antinous with a strong radial vignette (cos⁴ falloff to 45% in
  the corners) that differs per view (its centre follows the camera), as uncalibrated
  lenses give: prediction from other views must absorb brightness changes.
- ``buddha_occluder``: hci_buddha with a synthetic foreground bar (a textured strip at 4 px
  per view of disparity) occluding different parts of every view.
- ``layers_9x9``: a synthetic 9×9 grid of 320×256 px: a background and two occluding
  foreground shapes textured with photographs from the LLFF captures, at disparities of
  -0.35, 0.9 and 2.2 px per view (bicubic sub-pixel shifts), plus sensor-like noise (σ = 1.5).
- ``antinous_5x5_wide``: every second view of hci_antinous: a 5×5 grid with twice the baseline.
- ``dino_grey16``: lytro_dino_2067 as 16-bit greyscale (BT.601 luma × 257), 1 channel.
- ``antinous_exposure``: hci_antinous with a gain per view drawn uniformly from [0.9, 1.1]
  (seed 5), as a camera array whose cameras set their own exposure gives: every view is
  brighter or darker than its neighbours by up to 20%, everywhere.
- ``antinous_whitebalance``: hci_antinous with a gain per view and colour channel drawn
  uniformly from [0.94, 1.06] (seed 6), as a camera array whose cameras set their own white
  balance gives: every view's colours are tinted its own way (a per-RGB gain is not a gain per
  YCoCg plane: the codec's weighted prediction fits it only approximately).
- ``antinous_jitter``: hci_antinous with every view shifted by its own sub-pixel offset drawn
  uniformly from ±0.7 px in each axis (bilinear, seed 5), as a rig whose cameras are not on an
  exact grid gives: the views' parallax is no longer a multiple of their grid position.
- ``antinous_rotate``: hci_antinous with every view rotated about its centre by its own angle,
  uniform in ±0.5° (bilinear, seed 7), as a rig whose cameras are not rectified gives: the
  corners move by up to 3 px, a different way in every view, and no disparity is a shift.
- ``antinous_zoom``: hci_antinous with every view scaled about its centre by its own factor,
  uniform in 1 ± 0.6% (bilinear, seed 8): focal lengths that differ from camera to camera, or
  focus breathing (up to 1.5 px at the edges).
- ``antinous_jpeg85``: hci_antinous with every view JPEG-coded at quality 85 (OpenCV, 4:2:0), as
  rigs that store JPEG deliver them: each view carries 8×8 block artefacts no other view predicts.
- ``layers_rgba_9x9``: the two foreground layers of ``layers_9x9`` alone, RGBA (a renderer's
  output with transparency): colour over black where nothing is, alpha their soft-edged
  coverage, no noise. Its JPEG 2000 peer codes the colour and keeps the alpha exact (zlib).

For each: per-view JPEG 2000 (imagecodecs) at several PSNRs, interpolated at the target like
tools/bench.py; and the RLFC profile at the target (the CLI's ``--target-psnr``), with the
whole ``.lfc`` file counted. Writes ``unseen.json`` and ``unseen.md`` to DIR (and, with
``--save-scenes``, each scene as a folder that ``lfcodec encode`` and ``tools.bench_render`` read:
PNG views and a ``scene.json``).
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import cv2
import numpy as np

from formats.lightfield import LightField, grid_positions
from formats.metrics import bpp, psnr_rgb
from formats.scenes import read_scene, write_views
from formats.codec_api import EncodeOptions
from rlfc import encode
from tools.bench import bpp_at
from tools.common import lfc_bytes
from tools.common import log as _log
from tools.peers import j2k


def _grid(views: np.ndarray, name: str) -> LightField:
    r, c = views.shape[:2]
    f = float(max(views.shape[2:4]))
    return LightField(views=np.ascontiguousarray(views), positions=grid_positions(r, c), focal=(f, f),
                      layout="grid", meta={"source": name})


def save_scene(folder: Path, lf: LightField) -> None:
    """A variant as a scene folder that ``lfcodec encode``, ``tools.bench_render`` and
    :func:`formats.scenes.read_scene` read: ``rRR_cCC.png`` views (16-bit PNG for uint16) and a
    ``scene.json`` (a grid; baseline and focal left to the readers' defaults, which are the ones
    :func:`_grid` gives; its derivation as the source)."""
    write_views(folder, lf.views)
    doc = {"layout": "grid", "rows": lf.rows, "cols": lf.cols, "views": "r{row:02d}_c{col:02d}.png",
           "baseline": None, "focal_px": None,
           "source": f"derived by tools/unseen.py: {lf.meta.get('source', '')} (from ../shared/data: see the "
                     "source scenes' own provenance)",
           "license": "that of the scenes it is derived from (../shared/data/README.md)"}
    (Path(folder) / "scene.json").write_text(json.dumps(doc, indent=1) + "\n")


def _textures(data: Path, scenes: tuple, h: int, w: int) -> list:
    """The first view of each LLFF capture in ``scenes``, RGB float32, resized to (h + 80, w + 80)
    (a 40 px margin on every side for the layers' shifts)."""
    tex = []
    for s in scenes:
        sv = read_scene(data / s).views
        v = sv.reshape(-1, *sv.shape[2:])[0].astype(np.float32)
        tex.append(cv2.resize(v[..., :3], (w + 80, h + 80), interpolation=cv2.INTER_AREA))
    return tex


def _rect(h: int, w: int) -> np.ndarray:
    """The rectangular foreground layer's mask, over the textures' (h + 80, w + 80)."""
    yy, xx = np.mgrid[0:h + 80, 0:w + 80]
    return ((np.abs(yy - (h + 80) * 0.35) < 0.18 * h) & (np.abs(xx - (w + 80) * 0.68) < 0.16 * w)).astype(np.float32)


def _placed(img: np.ndarray, mask, d: float, r: int, c: int, rows: int, cols: int, h: int, w: int) -> tuple:
    """A layer of disparity ``d`` px per view step as view (r, c) sees it: (its texture bicubic,
    its mask bilinear (h, w, 1), or None without one)."""
    dy, dx = (r - rows // 2) * d, (c - cols // 2) * d
    m = np.float32([[1, 0, dx + 40], [0, 1, dy + 40]])
    warped = cv2.warpAffine(img, m, (w, h), flags=cv2.INTER_CUBIC | cv2.WARP_INVERSE_MAP, borderMode=cv2.BORDER_REFLECT)
    if mask is None:
        return warped, None
    return warped, cv2.warpAffine(mask, m, (w, h), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP)[..., None]


def layers(data: Path, rows=9, cols=9, h=256, w=320, seed=0) -> LightField:
    """Three textured layers with occlusion at sub-pixel disparities, plus noise."""
    tex = _textures(data, ("llff_statue", "llff_ollie", "llff_canclip"), h, w)
    yy, xx = np.mgrid[0:h + 80, 0:w + 80]
    disc = ((yy - (h + 80) * 0.55) ** 2 + (xx - (w + 80) * 0.35) ** 2 < (0.28 * h) ** 2).astype(np.float32)
    layers_ = [(tex[0], None, -0.35), (tex[1], disc, 0.9), (tex[2], _rect(h, w), 2.2)]
    rng = np.random.default_rng(seed)
    out = np.zeros((rows, cols, h, w, 3), np.uint8)
    for r in range(rows):
        for c in range(cols):
            acc = np.zeros((h, w, 3), np.float32)
            for img, mask, d in layers_:
                warped, a = _placed(img, mask, d, r, c, rows, cols, h, w)
                acc = warped if a is None else acc * (1 - a) + warped * a
            acc += rng.normal(0, 1.5, acc.shape).astype(np.float32)
            out[r, c] = np.clip(np.rint(acc), 0, 255).astype(np.uint8)
    return _grid(out, "synthetic layers (textures: LLFF statue, ollie, canclip)")


def layers_rgba(data: Path, rows=9, cols=9, h=256, w=320) -> LightField:
    """The two foreground layers of :func:`layers` alone, as RGBA: colour premultiplied over
    black (what a renderer writes where nothing is), alpha their soft-edged coverage (a disc at
    0.9 and a rectangle at 2.2 px per view step, occluding each other), no noise."""
    tex = _textures(data, ("llff_ollie", "llff_canclip"), h, w)
    yy, xx = np.mgrid[0:h + 80, 0:w + 80]
    disc = np.clip(0.28 * h - np.hypot(yy - (h + 80) * 0.55, xx - (w + 80) * 0.35) + 0.5, 0, 1).astype(np.float32)
    layers_ = ((tex[0], disc, 0.9), (tex[1], _rect(h, w), 2.2))
    out = np.zeros((rows, cols, h, w, 4), np.uint8)
    for r in range(rows):
        for c in range(cols):
            col, cov = np.zeros((h, w, 3), np.float32), np.zeros((h, w, 1), np.float32)
            for img, mask, d in layers_:
                warped, a = _placed(img, mask, d, r, c, rows, cols, h, w)
                col = col * (1 - a) + warped * a
                cov = cov * (1 - a) + a
            out[r, c, ..., :3] = np.clip(np.rint(col), 0, 255).astype(np.uint8)
            out[r, c, ..., 3] = np.clip(np.rint(cov[..., 0] * 255), 0, 255).astype(np.uint8)
    return _grid(out, "synthetic RGBA layers over nothing (textures: LLFF ollie, canclip)")


def noisy(views: np.ndarray, sigma: float, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.clip(np.rint(views + rng.normal(0, sigma, views.shape)), 0, 255).astype(np.uint8)


def vignetted(views: np.ndarray) -> np.ndarray:
    """cos⁴-like radial falloff to 45% in the corners; the centre moves with the view."""
    r, c, h, w, _ = views.shape
    out = np.empty_like(views)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    for i in range(r):
        for j in range(c):
            cy, cx = h / 2 + (i - r // 2) * h * 0.03, w / 2 + (j - c // 2) * w * 0.03
            d = np.hypot((yy - cy) / (h / 2), (xx - cx) / (w / 2)) / np.sqrt(2)
            g = (np.cos(np.clip(d, 0, 1) * 0.9) ** 4)[..., None]
            out[i, j] = np.clip(np.rint(views[i, j] * g), 0, 255).astype(np.uint8)
    return out


def _gained(views: np.ndarray, channels: int, spread: float, seed: int) -> np.ndarray:
    """Every view times its own gains (one, or one per channel: ``channels`` 1 or C), uniform in
    [1 − spread, 1 + spread], rounded to uint8."""
    rng = np.random.default_rng(seed)
    g = rng.uniform(1 - spread, 1 + spread, views.shape[:2] + (1, 1, channels))
    return np.clip(np.rint(views * g), 0, 255).astype(np.uint8)


def exposed(views: np.ndarray, spread: float = 0.1, seed: int = 5) -> np.ndarray:
    """Every view times its own gain, uniform in [1 − spread, 1 + spread]."""
    return _gained(views, 1, spread, seed)


def white_balanced(views: np.ndarray, spread: float = 0.06, seed: int = 6) -> np.ndarray:
    """Every view's channels times their own gains, uniform in [1 − spread, 1 + spread]."""
    return _gained(views, views.shape[-1], spread, seed)


def jittered(views: np.ndarray, reach: float = 0.7, seed: int = 5) -> np.ndarray:
    """Every view shifted by its own (dy, dx), uniform in ±``reach`` px (bilinear, edges reflected)."""
    rng = np.random.default_rng(seed)
    r, c = views.shape[:2]
    shifts = [rng.uniform(-reach, reach, 2) for _ in range(r * c)]
    return _warped(views, [[[1, 0, dx], [0, 1, dy]] for dy, dx in shifts])


def _warped(views: np.ndarray, matrices) -> np.ndarray:
    """Every view warped by its own 2×3 affine matrix (bilinear, edges reflected), rounded to its dtype."""
    r, c, h, w, _ = views.shape
    out = np.empty_like(views)
    hi = np.iinfo(views.dtype).max
    for (i, j), m in zip(np.ndindex(r, c), matrices):
        got = cv2.warpAffine(views[i, j].astype(np.float32), np.float32(m), (w, h), flags=cv2.INTER_LINEAR,
                             borderMode=cv2.BORDER_REFLECT)
        out[i, j] = np.clip(np.rint(got), 0, hi).astype(views.dtype).reshape(h, w, -1)
    return out


def rotated(views: np.ndarray, degrees: float = 0.5, seed: int = 7) -> np.ndarray:
    """Every view rotated about its centre by its own angle, uniform in ±``degrees`` (a rig whose
    cameras are not rectified: 0.5° moves a 512² view's corners by up to 3 px)."""
    rng = np.random.default_rng(seed)
    r, c, h, w, _ = views.shape
    return _warped(views, [cv2.getRotationMatrix2D((w / 2 - 0.5, h / 2 - 0.5), a, 1.0)
                           for a in rng.uniform(-degrees, degrees, r * c)])


def zoomed(views: np.ndarray, spread: float = 0.006, seed: int = 8) -> np.ndarray:
    """Every view scaled about its centre by its own factor, uniform in 1 ± ``spread`` (focal
    lengths that differ from camera to camera, or focus breathing: ±1.5 px at a 512² view's edges)."""
    rng = np.random.default_rng(seed)
    r, c, h, w, _ = views.shape
    return _warped(views, [cv2.getRotationMatrix2D((w / 2 - 0.5, h / 2 - 0.5), 0.0, z)
                           for z in rng.uniform(1 - spread, 1 + spread, r * c)])


def jpeg_sourced(views: np.ndarray, quality: int = 85) -> np.ndarray:
    """Every view JPEG-coded and decoded at ``quality`` (OpenCV, 4:2:0), as rigs that store JPEG
    deliver them: each view carries its own 8×8 block artefacts, which no other view predicts."""
    out = np.empty_like(views)
    for i, j in np.ndindex(views.shape[:2]):
        ok, enc = cv2.imencode(".jpg", np.ascontiguousarray(views[i, j, ..., ::-1]), [cv2.IMWRITE_JPEG_QUALITY, quality])
        out[i, j] = cv2.imdecode(enc, cv2.IMREAD_COLOR)[..., ::-1]
    return out


def occluded(views: np.ndarray, disparity: float = 4.0) -> np.ndarray:
    """A textured vertical bar in front of the scene, moving ``disparity`` px per view step."""
    r, c, h, w, ch = views.shape
    rng = np.random.default_rng(1)
    tex = cv2.GaussianBlur(rng.integers(0, 256, (h, w + int(abs(disparity) * c) + 64, ch)).astype(np.float32),
                           (0, 0), 2.0)
    tex = (tex - tex.min()) / np.ptp(tex) * 200 + 20
    out = views.copy()
    x0, bw = w // 3, max(8, w // 8)
    for i in range(r):
        for j in range(c):
            dx = (j - c // 2) * disparity
            m = np.float32([[1, 0, -dx], [0, 1, 0]])
            bar = cv2.warpAffine(tex, m, (tex.shape[1], h), flags=cv2.INTER_CUBIC, borderMode=cv2.BORDER_REFLECT)[:, :w]
            lo, hi = int(round(x0 + dx)), int(round(x0 + dx)) + bw
            lo, hi = max(0, lo), min(w, hi)
            if hi > lo:
                out[i, j, :, lo:hi] = np.clip(np.rint(bar[:, lo:hi]), 0, 255).astype(np.uint8).reshape(h, hi - lo, ch)
    return out


def scenes(data: Path) -> dict[str, LightField]:
    ant = read_scene(data / "hci_antinous")
    dino = read_scene(data / "lytro_dino_2067")
    bud = read_scene(data / "hci_buddha")
    y = dino.views.astype(np.float64) @ np.array([0.299, 0.587, 0.114])
    grey16 = np.clip(np.rint(y * 257), 0, 65535).astype(np.uint16)[..., None]
    return {"antinous_noise3": _grid(noisy(ant.views, 3.0), "hci_antinous + Gaussian noise sigma 3"),
            "antinous_vignette": _grid(vignetted(ant.views), "hci_antinous, per-view vignetting"),
            "buddha_occluder": _grid(occluded(bud.views), "hci_buddha + a foreground bar at 4 px/view"),
            "layers_9x9": layers(data), "antinous_5x5_wide": _grid(ant.views[::2, ::2], "hci_antinous[::2, ::2]"),
            "dino_grey16": _grid(grey16, "lytro_dino_2067 luma x257"),
            "antinous_exposure": _grid(exposed(ant.views), "hci_antinous, a gain per view in [0.9, 1.1]"),
            "antinous_jitter": _grid(jittered(ant.views), "hci_antinous, each view shifted by up to 0.7 px"),
            "antinous_whitebalance": _grid(white_balanced(ant.views),
                                           "hci_antinous, a gain per view and channel in [0.94, 1.06]"),
            "antinous_rotate": _grid(rotated(ant.views), "hci_antinous, each view rotated by up to 0.5 deg"),
            "antinous_zoom": _grid(zoomed(ant.views), "hci_antinous, each view scaled by 1 +- 0.6%"),
            "antinous_jpeg85": _grid(jpeg_sourced(ant.views), "hci_antinous, each view JPEG quality 85"),
            "layers_rgba_9x9": layers_rgba(data)}


def j2k_at(lf: LightField, target: float) -> tuple[float | None, list]:
    """Per-view JPEG 2000's bpp at ``target`` dB (colour PSNR), interpolated between levels
    (views with alpha: the alpha plane exact beside the colour, :class:`tools.peers.PerViewImageCodec`)."""
    views = lf.views.reshape(-1, *lf.views.shape[2:])
    peer, pts = j2k(), []
    for lev in (target - 4, target - 2, target, target + 2, target + 4, target + 6):
        r = peer.run(views, lev)
        pts.append({"codec": "j2k", "bpp": bpp(r["bytes"], len(views), lf.height, lf.width),
                    "psnr_rgb": psnr_rgb(views, r["decoded"])})
    return bpp_at(pts, "j2k", target), pts


def rlfc_at(lf: LightField, target: float, profile: str) -> dict:
    t = time.perf_counter()
    e = encode(lf, EncodeOptions(target_psnr=target, profile=profile))
    blob = lfc_bytes("rlfc", 1, e.config, lf.geometry(), e.sections)
    return {"bpp": bpp(len(blob), lf.rows * lf.cols, lf.height, lf.width),
            "psnr_rgb": psnr_rgb(lf.views, e.decoded), "blocks": e.config["n_blocks"],
            "sections": {n: len(x) for n, x in e.sections}, "encode_s": time.perf_counter() - t}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m tools.unseen", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("data", help="the shared data folder (../shared/data)")
    ap.add_argument("--out", required=True)
    ap.add_argument("--target", type=float, default=40.0)
    ap.add_argument("--only", default="", help="comma-separated scene names to run (default all)")
    ap.add_argument("--save-scenes", action="store_true")
    ap.add_argument("--profile", default="tx", help="RLFC profile (default tx)")
    a = ap.parse_args(argv)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    result = {}
    lines = [f"| grid | views | size (H×W×C) | JPEG 2000 bpp at {a.target:g} dB | {a.profile} bpp | PSNR_RGB | "
             "ratio to JPEG 2000 | coded blocks | encode s |", "|---|---|---|---|---|---|---|---|---|"]
    for name, lf in scenes(Path(a.data)).items():
        if a.only and name not in a.only.split(","):
            continue
        _log(f"[{name}] {lf.rows}x{lf.cols} of {lf.height}x{lf.width}x{lf.channels} {lf.views.dtype}")
        if a.save_scenes:
            save_scene(out / name, lf)
        jb, pts = j2k_at(lf, a.target)
        r = rlfc_at(lf, a.target, a.profile)
        r.update({"j2k_bpp": jb, "j2k_points": pts})
        result[name] = r
        ratio = f"{r['bpp'] / jb:.2f}×" if jb else "—"
        lines.append(f"| {name} | {lf.rows}×{lf.cols} | {lf.height}×{lf.width}×{lf.channels} {lf.views.dtype} | "
                     f"{jb:.3f} | {r['bpp']:.4f} | {r['psnr_rgb']:.2f} | {ratio} | {r['blocks']} | {r['encode_s']:.0f} |"
                     if jb else f"| {name} | … | … | — | {r['bpp']:.4f} | {r['psnr_rgb']:.2f} | — | | |")
        _log("  " + lines[-1])
    (out / "unseen.json").write_text(json.dumps(result, indent=1, default=float))
    (out / "unseen.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
