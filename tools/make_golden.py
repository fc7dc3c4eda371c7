"""Write the golden .lfc fixtures in tests/data/golden/ and the hashes of their decoded pixels.

The fixtures are decoded by the test suite for ever (tests/test_golden.py): a change that
alters how an existing file decodes fails there. Run this only to add a fixture for a new
codec version or profile; never to refresh an existing one.

    python -m tools.make_golden [--only NAME ...]

Inputs: a 4x4-view, 29x37-pixel crop of samples/dino_crop (a real Lytro capture; provenance in
samples/dino_crop/PROVENANCE.md), and derived 16-bit grey+alpha / RGBA variants.
"""
from __future__ import annotations

import argparse
import contextlib
import hashlib
import json
from pathlib import Path

import numpy as np

from formats.lfcfile import open_lfc, write_lfc
from formats.lightfield import LightField, grid_positions
from formats.scenes import read_scene

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "tests" / "data" / "golden"


def sample_crop() -> np.ndarray:
    """(4, 4, 29, 37, 3) uint8: views (2..5, 2..5), pixels y 40..68, x 60..96 of the sample."""
    lf = read_scene(ROOT / "samples" / "dino_crop")
    return np.ascontiguousarray(lf.views[2:6, 2:6, 40:69, 60:97])


def variants() -> dict[str, np.ndarray]:
    rgb = sample_crop()
    grey = rgb.astype(np.uint32) @ np.array([77, 150, 29], np.uint32) // 256          # (4,4,29,37)
    alpha = np.where(grey > np.median(grey), 255, 0)
    ga16 = (np.stack([grey, alpha], -1) * 257).astype(np.uint16)
    rgba = np.concatenate([rgb, alpha[..., None].astype(np.uint8)], -1)
    return {"rgb8": rgb, "ga16": ga16, "rgba8": rgba}


def exposed(views: np.ndarray) -> np.ndarray:
    """``views`` with a gain per view drawn from [0.85, 1.15] (seed 7): a camera array's exposures."""
    g = np.random.default_rng(7).uniform(0.85, 1.15, views.shape[:2] + (1, 1, 1))
    return np.clip(np.rint(views * g), 0, 255).astype(np.uint8)


def lf_of(views: np.ndarray) -> LightField:
    r, c = views.shape[:2]
    return LightField(views=views, positions=grid_positions(r, c), layout="grid", meta={"reader": "golden"})


def digest(a: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(a).tobytes()).hexdigest()


def decoded_hashes(path: Path) -> dict:
    """sha256 of every level's full decode and of all blocks, batched (the same bytes every
    decoder must produce)."""
    from formats.registry import open_decoder

    with open_lfc(path) as f:
        d = open_decoder(f)
        out = {"levels": {}, "shape": None}
        for level in range(d.levels + 1):
            full = d.decode_all(level)
            out["levels"][str(level)] = digest(full)
            out["shape"] = list(full.shape)
        return out


def rlfc_fixtures() -> dict:
    """name → (Encoded, LightField) of every RLFC fixture."""
    from rlfc import encode

    v = variants()
    specs = {
        "rlfc_bise_lossless_rgb8": (v["rgb8"], dict(profile="bise", block_size=8, quant=1)),
        "rlfc_bise_lossy_rgb8": (v["rgb8"], dict(profile="bise", block_size=8, quant=8, threshold=4, energy=16)),
        "rlfc_bise_lossy_rgba8": (v["rgba8"], dict(profile="bise", block_size=4, quant=6, threshold=3, energy=9,
                                                   top_psnr=36)),
        "rlfc_dcp_lossless_rgb8": (v["rgb8"], dict(profile="dcp", block_size=8, quant=1)),
        "rlfc_dcp_lossy_rgb8": (v["rgb8"], dict(profile="dcp", block_size=8, quant=6, threshold=3, energy=9,
                                                top_psnr=38)),
        "rlfc_dcp_lossy_ga16": (v["ga16"], dict(profile="dcp", block_size=4, quant=6 * 257, threshold=3 * 257,
                                                energy=9 * 257 ** 2, top_psnr=40)),
    }
    specs.update({
        "rlfc_tx_lossless_rgb8": (v["rgb8"], dict(profile="tx", block_size=16, quant=1)),
        "rlfc_tx_lossy_rgb8": (v["rgb8"], dict(profile="tx", block_size=16, step=5.0, key_spacing=2)),
        "rlfc_tx_lossy_ga16": (v["ga16"], dict(profile="tx", block_size=8, step=6.0 * 257, key_spacing=2)),
        "rlfc_tx_lossy_rgba8": (v["rgba8"], dict(profile="tx", block_size=16, step=4.0, key_spacing=3)),
        # tx layout version 2 (rANS tables built in integers); the rlfc_tx_* files above are version 1
        "rlfc_tx2_lossless_ga16": (v["ga16"], dict(profile="tx", block_size=16, quant=1)),
        "rlfc_tx2_lossy_rgb8": (v["rgb8"], dict(profile="tx", block_size=16, step=5.0, key_spacing=2)),
        "rlfc_tx2_lossy_rgba8": (v["rgba8"], dict(profile="tx", block_size=8, step=4.0, key_spacing=3)),
        # tx.maps version 3 (one context per escape digit position), with escapes: the maps'
        # corrections pushed far off on a third of the blocks (see far_maps)
        "rlfc_tx3_lossy_rgb8": (v["rgb8"], dict(profile="tx", block_size=8, step=5.0, key_spacing=3)),
        # tx layout version 3: each key-view block row coded as key_split streams (here one per block)
        "rlfc_txsplit_lossy_rgb8": (v["rgb8"], dict(profile="tx", block_size=8, step=3.0, key_spacing=3,
                                                    intra_codec="tx", key_split=5)),
        # tx layout version 4: weighted prediction, on the crop with a gain per view (0.85..1.15)
        "rlfc_tx4_weighted_rgb8": (exposed(v["rgb8"]), dict(profile="tx", block_size=8, step=4.0, key_spacing=3,
                                                            intra_codec="tx", weighted=True)),
        # tx layout version 5: per-view warps, on the crop with each view shifted by its own
        # sub-pixel offset (up to 0.7 px), coded with fixed warps (see fixed_warps)
        "rlfc_tx5_warped_rgb8": (shifted(v["rgb8"]), dict(profile="tx", block_size=8, step=4.0, key_spacing=3,
                                                          intra_codec="tx", warps=True)),
        # tx layout version 6: views with alpha as JPEG 2000 colour + an exact alpha stream (zlib);
        # 8-bit RGBA with one view predicted from them, and 16-bit grey + alpha (every view JPEG 2000)
        "rlfc_tx6_alpha_rgba8": (v["rgba8"], dict(profile="tx", block_size=8, step=8.0, key_spacing=3,
                                                  intra_codec="j2k")),
        "rlfc_tx6_alpha_ga16": (v["ga16"], dict(profile="tx", block_size=8, step=8.0 * 257, key_spacing=3,
                                                intra_codec="j2k")),
    })
    out = {}
    for name, (views, kw) in specs.items():
        with far_maps() if name == "rlfc_tx3_lossy_rgb8" else fixed_warps() if name == "rlfc_tx5_warped_rgb8" \
                else contextlib.nullcontext():
            out[name] = (encode(lf_of(views), **kw), lf_of(views))
    return out


@contextlib.contextmanager
def far_maps():
    """The tx encoder's maps, with a third of the blocks' disparities moved 31..4999 sixteenths of
    a pixel per view step off (deterministic): corrections that escape, with all three escape
    digits in use, which the sample's small parallax never makes. Yields a dict that holds the
    last maps made (``base``, ``disp``)."""
    import rlfc.txencode as te

    real = te.estimate_maps
    made: dict = {}

    def far(*a, **k):
        base, disp, modes = real(*a, **k)[:3]
        rng = np.random.default_rng(3)
        hit = rng.random(disp.shape) < 1 / 3
        disp = disp.copy()
        disp[hit] += rng.choice([-1, 1], int(hit.sum())) * rng.integers(31, 5000, int(hit.sum()))
        made.update(base=base, disp=disp)
        # (the estimate's costs were those of the maps before the move: none for a repricing)
        return (base, disp, modes, None) if k.get("with_costs") else (base, disp, modes)

    te.estimate_maps = far
    try:
        yield made
    finally:
        te.estimate_maps = real


def shifted(views: np.ndarray) -> np.ndarray:
    """``views`` each shifted by its own offset within ±0.7 px (seed 5, bilinear, edges
    replicated): a rig that is not rectified."""
    import cv2

    r, c = views.shape[:2]
    rng = np.random.default_rng(5)
    out = np.empty_like(views)
    for i in range(r):
        for j in range(c):
            dx, dy = rng.uniform(-0.7, 0.7, 2)
            out[i, j] = cv2.warpAffine(views[i, j], np.float64([[1, 0, dx], [0, 1, dy]]), views.shape[3:1:-1],
                                       flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return out


@contextlib.contextmanager
def fixed_warps():
    """The tx encoder's per-view warps set, not estimated (views this small give the estimate too
    little to fit): a, b within ±2^8 (±0.4% scale, ±0.22°), cx, cy within ±2^8 (±1 px), seed 11,
    so that every term of the offsets is exercised."""
    import rlfc.txencode as te

    real = te.TxEncoder._estimate_warps

    def fixed(self, lf):
        rng = np.random.default_rng(11)
        n = self.n0
        self.s.warp = rng.integers(-(1 << 8), 1 << 8, (n, 4)).astype(np.int64)
        self.warp_report = {"applied": True, "largest_correction_px": None}

    te.TxEncoder._estimate_warps = fixed
    try:
        yield
    finally:
        te.TxEncoder._estimate_warps = real


#: LFN fixtures this tool writes (name: codec version). ``lfn_tiny_rgba8`` (codec version 1: one
#: section per step, sizes named *_width, cameras in meta) was written by an earlier version of
#: this tool and is kept as it is.
LFN_FIXTURES = {"lfn3_tiny_rgba8": 3}


def lfn_fixture(index: dict, out: Path, name: str = "lfn3_tiny_rgba8") -> None:
    """A tiny nested-width LFN (depth 2, widths 4..8) trained briefly on the RGBA crop; the
    expected renders are stored as .npy (float networks match within 1 LSB, not bit for bit).
    Version 3: one lfn.steps section (checksum chunks of 64 bytes here, so that prefixes are
    tested on a tiny file), the cameras in meta.more."""
    import torch

    from lfn_stream import MOVED_KEYS, LfnConfig, LfnRenderer, TrainOptions, to_sections, train

    torch.manual_seed(0)
    lf = lf_of(variants()["rgba8"])
    cfg = LfnConfig(depth=2, min_neurons=4, max_neurons=8, occupancy_neurons=4)
    model, occ, info = train(lf, cfg, TrainOptions(steps=30, batch=256, holdout=0, seed=0))
    config, sections = to_sections(model, occ, info, "fp16")
    version = LFN_FIXTURES[name]
    path = out / f"{name}.lfc"
    sections = [(n, d, 64) if n == "lfn.steps" else (n, d) for n, d, *_ in sections]
    write_lfc(path, "lfn", version, config, lf.geometry(), sections, more=MOVED_KEYS)
    with open_lfc(path) as f:
        r = LfnRenderer(f, device="cpu")
        renders = np.stack([r.decode_view(1, 2, r.neurons - n) for n in (4.0, 6.5, 8.0)])
    np.save(out / f"{name}.expected.npy", renders, allow_pickle=False)
    index[name] = {"file": path.name, "bytes": path.stat().st_size, "view": [1, 2], "version": version,
                   "neurons": [4.0, 6.5, 8.0], "expected": f"{name}.expected.npy", "shape": list(renders.shape)}
    print(name, path.stat().st_size, "bytes")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="*", help="write only these fixtures (names without .lfc)")
    ap.add_argument("--out", default=str(OUT), help="folder (default tests/data/golden; another folder to "
                                                     "check that today's encoder still writes the same bytes)")
    a = ap.parse_args(argv)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    index_path = out / "golden.json"
    index = json.loads(index_path.read_text()) if index_path.exists() else {}
    for name, (enc, lf) in rlfc_fixtures().items():
        if a.only and name not in a.only:
            continue
        path = out / f"{name}.lfc"
        write_lfc(path, "rlfc", 1, enc.config, lf.geometry(), enc.sections)
        index[name] = {"file": path.name, "bytes": path.stat().st_size, **decoded_hashes(path)}
        print(name, index[name]["bytes"], "bytes")
    for name in LFN_FIXTURES:
        if not a.only or name in a.only:
            lfn_fixture(index, out, name)
    index_path.write_text(json.dumps(index, indent=1, sort_keys=True) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
