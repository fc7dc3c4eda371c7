"""The ``lfcodec`` command line: a thin ``main(argv) -> int`` over the library.

Errors in input become one line on stderr and exit code 2.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from . import __version__
from .errors import LfcError, ParameterError


def _pair(text: str, n: int, what: str) -> tuple[int, ...]:
    try:
        vals = tuple(int(x) for x in text.split(","))
    except ValueError:
        vals = ()
    if len(vals) != n or any(v < 0 for v in vals):
        raise ParameterError(f"{what} must be {n} non-negative integers separated by commas, got {text!r}")
    return vals


def _progress(quiet: bool, total=None, desc=""):
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, disable=quiet, file=sys.stderr, leave=False)


# -- info ------------------------------------------------------------------------------------
def cmd_info(a) -> int:
    from .lfcfile import open_lfc

    with open_lfc(a.file) as f:
        if a.verify:
            f.container.verify_all()
        c = f.container
        meta = f.meta
        scene = meta.get("scene", {})
        cfg = meta.get("config", {})
        out = {
            "file": str(a.file), "bytes": c.size, "format_version": "%d.%d" % c.version, "codec": meta.get("codec"),
            "codec_version": meta.get("codec_version"), "encoder": meta.get("encoder"),
            "profile": cfg.get("profile"),
            "scene": {k: scene.get(k) for k in ("rows", "cols", "height", "width", "channels", "dtype", "layout",
                                                "focal")},
            "sections": [{"name": s.name, "offset": s.offset, "bytes": s.length, "chunks": s.n_chunks}
                         for s in c.sections.values()],
            "verified": bool(a.verify),
        }
        if {"rows", "cols", "height", "width"} <= scene.keys():
            out["bpp"] = 8.0 * c.size / (scene["rows"] * scene["cols"] * scene["height"] * scene["width"])
        for k in ("block_size", "n_blocks", "n_raw_blocks", "params", "network", "weights"):
            if k in cfg:
                out[k] = cfg[k]
        if "network" in cfg:
            out["levels"] = [cfg["network"].get("min_width"), cfg["network"].get("max_width")]
        if "tree" in cfg:
            out["tree_levels"] = cfg["tree"]["sizes"]
    if a.json:
        print(json.dumps(out, indent=1))
        return 0
    s = out["scene"]
    detail = f" (profile {out['profile']})" if out.get("profile") else ""
    print(f"{out['file']}: {out['bytes']} bytes, .lfc {out['format_version']}, codec {out['codec']} "
          f"v{out['codec_version']}{detail}, {out['encoder']}")
    print(f"scene: {s['rows']}x{s['cols']} views of {s['width']}x{s['height']}x{s['channels']} {s['dtype']} "
          f"({s['layout']})" + (f", {out['bpp']:.4f} bpp" if "bpp" in out else ""))
    if "tree_levels" in out:
        print(f"tree: nodes per level {out['tree_levels']}, block {out.get('block_size')} px, "
              f"{out.get('n_blocks')} residual blocks ({out.get('n_raw_blocks')} raw)")
    if "network" in out:
        n = out["network"]
        print(f"network: depth {n.get('depth')}, widths {n.get('min_width')}..{n.get('max_width')} "
              f"(levels; any prefix ending on a step section is a complete network), {out.get('weights')} weights")
    print("sections:")
    for sec in out["sections"]:
        print(f"  {sec['name']:<16} offset {sec['offset']:>10}  {sec['bytes']:>10} bytes  {sec['chunks']} chunk(s)")
    if a.verify:
        print("all checksums OK")
    return 0


# -- encode ----------------------------------------------------------------------------------
def _refuse_input_overwrite(scene: Path, out: Path) -> None:
    so, o = scene.resolve(), out.resolve()
    if o == so or (so.is_dir() and so in o.parents and o.exists()):
        raise ParameterError(f"{out}: refusing to write over a file of the input scene {scene}")


def cmd_encode(a) -> int:
    from rlfc import Encoder, RlfcParams
    from rlfc.color import from_planes
    from rlfc.encoder import CODEC_ID, CODEC_VERSION
    from rlfc.ratecontrol import default_quant, params_for_quant, search, search_dcp, search_dcp_bpp

    from .lfcfile import write_lfc
    from .metrics import bpp, psnr_rgb, psnr_ycocg, ssim
    from .scenes import read_scene

    scene, out = Path(a.scene), Path(a.out)
    _refuse_input_overwrite(scene, out)
    if out.parent and not out.parent.exists():
        raise ParameterError(f"{out}: folder {out.parent} does not exist")
    t0 = time.perf_counter()
    lf = read_scene(scene, baseline=a.baseline, focal=a.focal, split=a.split)
    profile = a.profile
    if profile == "auto":     # dcp wins on every grid measured (BENCHMARKS.md); posed captures need bise
        profile = "dcp" if lf.layout == "grid" else "bise"
    top_psnr = a.top_psnr
    lossless = a.quant is not None and a.quant <= 1
    if profile == "dcp" and top_psnr is None and not lossless:   # dcp key views are lossy by default
        top_psnr = a.target_psnr + 3 if a.target_psnr is not None else 44.0
    base = RlfcParams(tree_height=a.tree_height, block_size=a.block_size, sigma=a.sigma, top_codec=a.top_codec,
                      top_psnr=top_psnr, profile=profile, max_disparity=a.max_disparity,
                      disp_frac_bits=a.disparity_bits)
    search_trace = None
    bar = _progress(a.quiet, desc="rate control")

    def prog(i, p, ps, b):
        bar.update(1)
        bar.set_postfix(quant=p.quant, psnr=f"{ps:.2f}", **({"bpp": f"{b:.3f}"} if b is not None else {}))

    if profile == "dcp" and a.target_psnr is not None and a.top_psnr is None:
        # the key views' quality is the main knob: search_dcp returns a result with its blocks
        enc, params, res, search_trace = search_dcp(lf, base, target_psnr=a.target_psnr, fixed_threshold=a.threshold,
                                                    fixed_energy=a.energy, progress=prog)
    elif profile == "dcp" and a.target_bpp is not None and a.top_psnr is None:
        enc, params, res, search_trace = search_dcp_bpp(lf, base, target_bpp=a.target_bpp, progress=prog)
    else:
        enc = Encoder(lf, base)
        if a.target_psnr is not None or a.target_bpp is not None:
            params, res, search_trace = search(enc, base, target_psnr=a.target_psnr, target_bpp=a.target_bpp,
                                               fixed_threshold=a.threshold, fixed_energy=a.energy, progress=prog)
            if a.target_bpp is None:
                res = enc.closed_loop(params)     # the PSNR search ran without keeping blocks
        else:
            params = params_for_quant(base, a.quant if a.quant is not None else default_quant(lf.views.dtype),
                                      a.threshold, a.energy)
            res = enc.closed_loop(params)
    bar.close()
    cfg, sections = enc.pack(params, res)
    nbytes = write_lfc(out, CODEC_ID, CODEC_VERSION, cfg, lf.geometry(), sections,
                       extra={"source": {k: v for k, v in lf.meta.items() if k in ("reader", "assumed", "source", "license")}})
    enc_s = time.perf_counter() - t0
    if not a.json and a.quiet:
        return 0
    nv = lf.rows * lf.cols
    ref = lf.views.reshape(nv, lf.height, lf.width, lf.channels)
    dec = from_planes(res.dec0[:, :lf.height, :lf.width], lf.views.dtype)
    report = {"file": str(out), "bytes": nbytes, "bpp": bpp(nbytes, nv, lf.height, lf.width),
              "psnr_rgb": psnr_rgb(ref, dec), "psnr_ycocg": psnr_ycocg(ref, dec), "encode_s": round(enc_s, 3),
              "views": nv, "height": lf.height, "width": lf.width, "channels": lf.channels,
              "dtype": str(lf.views.dtype), "codec": CODEC_ID, "profile": params.profile, "params": params.to_dict()}
    if a.json:
        report["ssim"] = ssim(ref, dec)
        if a.target_psnr is not None:
            report["target_psnr"] = a.target_psnr
        if a.target_bpp is not None:
            report["target_bpp"] = a.target_bpp
        if search_trace:
            report["search"] = [{"quant": q, "psnr_rgb": p, "bpp": b} for q, p, b in search_trace]
        report["exact"] = report["psnr_rgb"] == float("inf")
        print(json.dumps({k: (None if isinstance(v, float) and (v != v or v in (float("inf"), -float("inf"))) else v)
                          for k, v in report.items()}))
    else:
        print(f"wrote {out}: {nbytes} bytes, {report['bpp']:.4f} bpp, PSNR_RGB {report['psnr_rgb']:.2f} dB, "
              f"PSNR_YCoCg {report['psnr_ycocg']:.2f} dB, quant {params.quant:g}, {enc_s:.1f} s")
    return 0


# -- decode ----------------------------------------------------------------------------------
def _save_npy(path: Path, arr: np.ndarray) -> None:
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}.npy")
    try:
        np.save(tmp, arr, allow_pickle=False)
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def _int_level(d, level: float):
    """RLFC levels are integers; LFN levels are fractional widths."""
    if hasattr(d, "block_size"):
        if level != int(level):
            raise ParameterError(f"RLFC --level must be an integer 0..{d.levels}, got {level}")
        return int(level)
    return level


def cmd_decode(a) -> int:
    from .codecs import open_decoder
    from .lfcfile import open_lfc
    from .scenes import write_views

    if a.block is not None and a.out is None:
        raise ParameterError("--block needs --out FILE.npy")
    if a.block is None and a.outdir is None:
        raise ParameterError("give an output folder (OUTDIR), or --block ROW,COL,BY,BX with --out FILE.npy")
    with open_lfc(a.input) as f:
        d = open_decoder(f)
        t0 = time.perf_counter()
        if a.block is not None:
            r, c, by, bx = _pair(a.block, 4, "--block")
            blk = d.decode_block(r, c, by, bx, level=_int_level(d, a.level))
            out = Path(a.out)
            _save_npy(out, blk)
            if not a.quiet:
                print(f"wrote {out}: block ({by},{bx}) of view ({r},{c}), shape {blk.shape} {blk.dtype}, "
                      f"level {a.level}, {1e3 * (time.perf_counter() - t0):.2f} ms")
            return 0
        outdir = Path(a.outdir)
        if outdir.exists() and not outdir.is_dir():
            raise ParameterError(f"{outdir}: exists and is not a folder")
        if a.view is not None:
            r, c = _pair(a.view, 2, "--view")
            img = d.decode_view(r, c, level=_int_level(d, a.level))
            paths = write_views(outdir, img[None, None], rows=[r], cols=[c])
        else:
            bar = _progress(a.quiet, total=d.rows, desc="decode")
            views = d.decode_all(level=_int_level(d, a.level))
            paths = []
            for r in range(d.rows):   # write row by row for the progress bar
                paths += write_views(outdir, views[r:r + 1], rows=[r])
                bar.update(1)
            bar.close()
        if not a.quiet:
            print(f"wrote {len(paths)} view(s) to {outdir} (level {a.level}) in {time.perf_counter() - t0:.2f} s")
    return 0


# -- parser ----------------------------------------------------------------------------------
def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="lfcodec", description="Light-field compression: encode, decode and inspect .lfc files.")
    p.add_argument("--version", action="version", version=f"lfcodec {__version__}")
    sub = p.add_subparsers(dest="cmd", required=True)

    i = sub.add_parser("info", help="show an .lfc file's sections, sizes, codec and scene geometry",
                       description="Show an .lfc file's sections, sizes, codec and scene geometry.")
    i.add_argument("file")
    i.add_argument("--json", action="store_true", help="print one JSON object")
    i.add_argument("--verify", action="store_true", help="check every checksum of every section")
    i.set_defaults(func=cmd_info)

    e = sub.add_parser("encode", help="encode a scene folder to an .lfc file (RLFC codec)",
                       description="Encode a light field (grid scene, HCI/Stanford folder, LLFF capture or "
                                   "transforms.json) to an .lfc file with the RLFC codec.")
    e.add_argument("scene", help="scene folder (or transforms*.json)")
    e.add_argument("out", help="output .lfc file (replaced atomically)")
    e.add_argument("--tree-height", type=int, default=3, help="key-view tree height (default 3)")
    e.add_argument("--block-size", type=int, default=8, help="residual block size in pixels (default 8)")
    e.add_argument("--threshold", type=float, default=None, help="pixel threshold T (default Q/2)")
    e.add_argument("--quant", type=float, default=None,
                   help="quantizer step Q in pixel units, 1 = lossless (default 8 for 8-bit input, 8*257 for 16-bit)")
    e.add_argument("--energy", type=float, default=None, help="block-energy threshold E (default (Q/2)^2)")
    g = e.add_mutually_exclusive_group()
    g.add_argument("--target-psnr", type=float, default=None, metavar="DB", help="choose Q for PSNR_RGB >= DB")
    g.add_argument("--target-bpp", type=float, default=None, metavar="X", help="choose Q for bpp <= X")
    e.add_argument("--lossless", action="store_const", dest="quant", const=1.0, help="same as --quant 1")
    e.add_argument("--sigma", type=float, default=1.0, help="Gaussian filter width (view spacings)")
    e.add_argument("--top-codec", default="auto", choices=["auto", "j2k", "jxl"], help="top key-view image codec")
    e.add_argument("--top-psnr", type=float, default=None,
                   help="lossy top level: JPEG 2000 at this PSNR (dcp default: target + 3 dB, or 44)")
    e.add_argument("--profile", default="auto", choices=["auto", "bise", "dcp"],
                   help="RLFC profile: dcp (disparity-compensated prediction from 3x3-cluster key views; grids), "
                        "bise (the paper's key-view tree), or auto (default: dcp for grids, bise for posed captures)")
    e.add_argument("--max-disparity", type=int, default=32,
                   help="dcp: largest disparity searched, px per view step (default 32; the search starts at 4 "
                        "and widens where blocks need it)")
    e.add_argument("--disparity-bits", type=int, default=3,
                   help="dcp: fractional bits of the disparity (3 = 1/8 px per view step; 0 = whole pixels)")
    e.add_argument("--baseline", type=float, default=None, help="grid baseline when the scene has none")
    e.add_argument("--focal", type=float, default=None, help="focal length in pixels when the scene has none")
    e.add_argument("--split", default="train", help="transforms_<split>.json to read (default train)")
    e.add_argument("--json", action="store_true", help="print one JSON object (bytes, bpp, PSNRs, SSIM, times)")
    e.add_argument("--quiet", action="store_true", help="no progress bars or messages")
    e.set_defaults(func=cmd_encode)

    d = sub.add_parser("decode", help="decode views, one view, or one block of an .lfc file",
                       description="Decode an .lfc file: all views as PNG (rRR_cCC.png), one view (--view), or "
                                   "one pixel block of one view (--block ROW,COL,BY,BX --out FILE.npy).")
    d.add_argument("input")
    d.add_argument("outdir", nargs="?", help="output folder for PNG views")
    d.add_argument("--view", metavar="ROW,COL", help="decode only this view")
    d.add_argument("--block", metavar="ROW,COL,BY,BX",
                   help="decode one block: view (ROW,COL), block row BY and column BX (pixels [BY*B,(BY+1)*B) x [BX*B,(BX+1)*B))")
    d.add_argument("--out", metavar="FILE.npy", help="where --block writes its (B, B, C) array")
    d.add_argument("--level", type=float, default=0,
                   help="RLFC: 0 = full quality .. H = top key views; LFN: network width (fractional), 0 = widest")
    d.add_argument("--quiet", action="store_true")
    d.set_defaults(func=cmd_decode)

    t = sub.add_parser("train", help="train a light field network (LFN stream) on a scene",
                       description="Train a nested-width light field network with continuous levels of detail and "
                                   "write it as an .lfc stream (any prefix of which is a smaller network).")
    t.add_argument("scene")
    t.add_argument("out")
    t.add_argument("--depth", type=int, default=6)
    t.add_argument("--min-width", type=int, default=16)
    t.add_argument("--max-width", type=int, default=128)
    t.add_argument("--occupancy-width", type=int, default=32, help="occupancy net width (used when the scene has alpha)")
    t.add_argument("--steps", type=int, default=2000)
    t.add_argument("--batch", type=int, default=4096)
    t.add_argument("--lr", type=float, default=3e-3)
    t.add_argument("--resolution", type=int, default=128, help="train at this many pixels on the long side (0 = full)")
    t.add_argument("--holdout", type=int, default=4, help="hold out every k-th view for evaluation (0 = none)")
    t.add_argument("--device", default="cpu")
    t.add_argument("--weights", default="fp16", choices=["fp16", "fp32"])
    t.add_argument("--checkpoint", default=None, help="checkpoint .npz (saved periodically; resumed from if present)")
    t.add_argument("--split", default="train")
    t.add_argument("--json", action="store_true")
    t.add_argument("--quiet", action="store_true")
    t.set_defaults(func=cmd_train)

    b = sub.add_parser("bench", help="run the benchmark suite (same as python -m tools.bench)",
                       description="Benchmark lfcodec against per-view JPEG 2000 / JPEG XL and HEVC.")
    b.add_argument("rest", nargs=argparse.REMAINDER)
    b.set_defaults(func=cmd_bench)
    return p


def cmd_train(a) -> int:
    from lfn_stream import CODEC_ID, CODEC_VERSION, LfnConfig, TrainOptions, to_sections, train

    from .lfcfile import write_lfc
    from .scenes import read_scene
    from .transform import resize_lightfield

    scene, out = Path(a.scene), Path(a.out)
    _refuse_input_overwrite(scene, out)
    lf = read_scene(scene, split=a.split)
    if a.resolution:
        lf = resize_lightfield(lf, a.resolution)
    cfg = LfnConfig(depth=a.depth, min_width=a.min_width, max_width=a.max_width, occupancy_width=a.occupancy_width)
    bar = _progress(a.quiet, total=a.steps, desc="train")
    opts = TrainOptions(steps=a.steps, batch=a.batch, lr=a.lr, holdout=a.holdout, device=a.device,
                        checkpoint=a.checkpoint)

    def prog(step, loss):   # called every 50 steps
        bar.n = step + 1
        bar.set_postfix(loss=f"{loss:.5f}")
        bar.refresh()

    model, occ, info = train(lf, cfg, opts, progress=prog)
    bar.close()
    config, sections = to_sections(model, occ, info, a.weights)
    nbytes = write_lfc(out, CODEC_ID, CODEC_VERSION, config, lf.geometry(), sections)
    rep = {"file": str(out), "bytes": nbytes, "steps": info["steps"], "train_s": round(info["train_s"], 1),
           "height": lf.height, "width": lf.width, "params": model.n_params(), "final_loss": opts.history[-1][1]}
    print(json.dumps(rep) if a.json else f"wrote {out}: {nbytes} bytes, {info['steps']} steps in {info['train_s']:.0f} s")
    return 0


def cmd_bench(a) -> int:
    try:
        from tools.bench import main as bench_main
    except ImportError:
        raise LfcError("the benchmark tools are not installed (run from a source checkout)") from None
    return bench_main(a.rest)


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    a = parser.parse_args(argv)
    try:
        return a.func(a)
    except LfcError as e:
        print(f"lfcodec: error: {e}", file=sys.stderr)
        return 2
    except BrokenPipeError:          # output piped into e.g. `head`: stop quietly
        try:
            sys.stdout = open(os.devnull, "w")
        except OSError:
            pass
        return 0
    except OSError as e:
        print(f"lfcodec: error: {e.filename or ''}: {e.strerror or e}".replace(": : ", ": "), file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("lfcodec: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
