"""``lfcodec encode`` and ``lfcodec train``: a scene read, encoded by its codec, written
atomically, and measured against the scene's views (:func:`cmd_encode`)."""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from .cli_checks import FILE_SUFFIXES, check_out_file, grid, is_set, refuse_input_overwrite
from .cli_output import Progress, dump_json
from .errors import ParameterError

def _unused_read_options(a, lf) -> list[str]:
    """Notes for the scene options the scene's reader did not use (they used to pass in silence:
    --grid 3x27 on a 9x9 folder with its own scene.json gave a 9x9 file)."""
    reader, out = lf.meta.get("reader"), []
    if a.grid is not None and reader not in ("folder", "npy") or reader == "npy" and a.grid is not None \
            and grid(a.grid) != (lf.rows, lf.cols):
        out.append(f"--grid {a.grid} was not used: the scene has its own layout ({reader}, {lf.rows}x{lf.cols} views)")
    if (a.baseline is not None or a.focal is not None) and reader in ("llff", "transforms", "npy"):
        out.append(f"--baseline/--focal were not used: the {reader} reader takes the cameras from the scene")
    if a.split != "train" and reader != "transforms":
        out.append(f"--split {a.split} was not used: the scene is not a capture with transforms_<split>.json files")
    return out


def cmd_encode(a, codec_id: str | None = None) -> int:
    from .codec_api import EncodeOptions
    from .lfcfile import write_lfc
    from .metrics import bpp, quality_report
    from .parallel import check_runner
    from .registry import get_codec
    from .scenes import read_scene

    codec_id = codec_id or a.codec
    codec = get_codec(codec_id)
    others = [dest for cid, dests in a._groups.items() if cid != codec_id for dest in dests
              if getattr(a, dest, None) is not None and dest not in a._groups.get(codec_id, ())]
    if others:
        raise ParameterError(f"option(s) {', '.join('--' + d.replace('_', '-') for d in others)} do not apply to "
                             f"codec {codec_id}")
    check_runner(getattr(a, "workers", 1), getattr(a, "scheduler", None))
    scene, out = Path(a.scene), Path(a.out)
    refuse_input_overwrite(scene, out)
    check_out_file(out)
    if out.suffix.lower() in FILE_SUFFIXES:          # (it wrote the container under that name, over any such file)
        raise ParameterError(f"{out}: encode writes an .lfc container, not a {out.suffix} image; name the output "
                             f"OUT.lfc (views as images: lfcodec decode FILE.lfc OUTDIR)")
    t0 = time.perf_counter()
    prog = Progress(a.quiet)
    try:
        # a grid's views stay in their files until the codec reads them (the tx encoder reads
        # them view by view, so the light field's pixels are never all in memory at once)
        lf = read_scene(scene, baseline=a.baseline, focal=a.focal, split=a.split, allow_outside=a.allow_outside_paths,
                        grid=grid(a.grid) if a.grid else None, progress=prog, lazy=True)
    finally:
        prog.close()
    if str(out.resolve()) in set(lf.meta.get("input_paths", ())):
        raise ParameterError(f"{out}: refusing to write over one of the input files of the scene")
    rectified = None
    if getattr(a, "rectify", False):
        from .rectify import rectify_grid

        lf, rectified = rectify_grid(lf)
    opts = EncodeOptions(target_psnr=a.target_psnr, target_bpp=a.target_bpp, min_view_psnr=a.min_view_psnr,
                         lossless=bool(a.lossless), profile=getattr(a, "profile", None) or "auto",
                         params=codec.params_from_args(a), workers=getattr(a, "workers", 1),
                         scheduler=getattr(a, "scheduler", None),
                         # a lossy grid's report measures the file written, a few views at a time,
                         # instead of holding a decoded copy of the light field (a lossless file's
                         # parse and a posed capture's decoder, which holds every view, use more)
                         keep_decoded=bool(a.lossless) or lf.layout != "grid")
    if codec.writes_set(opts):
        return _write_set(a, codec, lf, opts, out, t0)
    if is_set(out):
        raise ParameterError(f"{out}: this name is for a manifest of a set of files (e.g. --tiles K); name a single "
                             f"file OUT.lfc")
    prog = Progress(a.quiet)
    try:
        enc = codec.encode(lf, opts, prog)
    finally:
        prog.close()
    nbytes = write_lfc(out, codec.codec_id, codec.version, enc.config, lf.geometry(), enc.sections, more=enc.more,
                       extra={"source": {k: v for k, v in lf.meta.items()
                                         if k in ("reader", "assumed", "source", "license", "rectified")}})
    enc_s = time.perf_counter() - t0
    nv = lf.rows * lf.cols
    report = {"file": str(out), "bytes": nbytes, "bpp": bpp(nbytes, nv, lf.height, lf.width),
              "encode_s": round(enc_s, 3), "views": nv, "height": lf.height, "width": lf.width,
              "channels": lf.channels, "dtype": str(lf.views.dtype), "codec": codec.codec_id, **enc.summary}
    if enc.decoded is not None:
        ref = lf.views if isinstance(lf.views, np.ndarray) else np.asarray(lf.views)     # (a ViewStack: read)
        report.update(quality_report(ref, enc.decoded, with_ssim=a.json))
        del ref
    else:                             # the codec kept no decoded views: the file written, decoded
        report.update(_quality_of_file(out, lf, with_ssim=a.json, quiet=a.quiet))
    # every requested target is met, or the report says so
    notes, missed = list(enc.notes), []
    for sp in lf.meta.get("other_splits", ()):
        notes.append(f"{scene}: split '{sp}' (transforms_{sp}.json) was not encoded; encode it with --split {sp}, "
                     f"or every split as one capture with --split all")
    notes += _unused_read_options(a, lf)
    if rectified is not None:
        report["rectify"] = rectified
        px = rectified["largest_correction_px"]
        notes.append(f"--rectify: the views were resampled onto the rectified grid (the largest correction moved a "
                     f"corner by {px:g} px); the file holds them, and its PSNRs are against them"
                     if rectified["applied"] else
                     f"--rectify: the views are rectified already (no pixel would move by {px:g} px or more); "
                     f"they were coded as they are")
    wr = enc.summary.get("warps")
    if isinstance(wr, dict):                  # (tx --warps: stored, or why not)
        notes.append(_warps_note(wr))
    if (opts.workers > 1 or opts.scheduler is not None) and "runner" not in enc.summary:
        notes.append(f"{enc.summary.get('profile', codec.codec_id)} codes in this process only; "
                      "--workers/--scheduler had no effect")
    q = report.get("psnr_rgb")
    if a.target_psnr is not None and report.get("exact") is not True and (q is None or q < a.target_psnr - 1e-9):
        missed.append(f"target PSNR {a.target_psnr:g} dB not reached ({q:.2f} dB)")
    if a.target_bpp is not None and report["bpp"] > a.target_bpp:
        missed.append(f"target {a.target_bpp:g} bpp not reached ({report['bpp']:.4f} bpp)")
    if a.min_view_psnr is not None and report.get("psnr_view_min") is not None \
            and report["psnr_view_min"] < a.min_view_psnr - 1e-9:
        missed.append(f"per-view floor {a.min_view_psnr:g} dB not reached (worst view {report['psnr_view_min']:.2f} dB)")
    if a.lossless and report.get("exact") is False:
        missed.append("lossless requested but the decode is not exact")
    if a.target_psnr is not None or a.target_bpp is not None or a.min_view_psnr is not None or a.lossless:
        report["target_met"] = not missed and enc.target_met is not False
    if enc.trace:
        report["search"] = enc.trace
    report["notes"] = notes + missed
    for m in notes + missed:
        print(f"lfcodec: warning: {m}", file=sys.stderr)
    if a.json:
        print(dump_json(report))
    elif not a.quiet:
        label = "PSNR_RGB" if lf.channels >= 3 else "PSNR (grey)"       # psnr_rgb: the colour channels' PSNR
        quality = (f", {label} {q:.2f} dB" if q is not None else (", exact" if report.get("exact") else ""))
        if report.get("psnr_heldout") is not None:
            quality += (f", held-out PSNR {report['psnr_heldout']:.2f} dB on {report['heldout_views']} views "
                        f"(nearest training view {report['psnr_heldout_nearest_view']:.2f} dB)")
        print(f"wrote {out}: {nbytes} bytes, {report['bpp']:.4f} bpp{quality}, {enc_s:.1f} s")
    return 0


def _quality_of_file(path: Path, lf, *, with_ssim: bool, quiet: bool) -> dict:
    """:func:`formats.metrics.quality_report` of the file at ``path`` against the scene's views,
    decoded and compared a few views at a time (as the metrics chunk a light field: never a
    second copy of it)."""
    from .heap import trim
    from .lfcfile import open_lfc
    from .metrics import QualityAccumulator, views_per_chunk
    from .registry import open_decoder

    trim()           # (the decoder allocates beside the encoder's freed arenas otherwise)
    acc = QualityAccumulator(with_ssim=with_ssim, ssim_threads=1)    # (below the encode's peak)
    n = lf.rows * lf.cols
    k = views_per_chunk(lf.height * lf.width * lf.channels)
    prog = Progress(quiet)
    try:
        with open_lfc(path) as f:
            d = open_decoder(f)
            for i in range(0, n, k):
                vs = np.arange(i, min(i + k, n))
                ref = np.stack([np.asarray(lf.views[v // lf.cols, v % lf.cols]) for v in vs.tolist()])
                acc.add(ref, d.decode_views(vs).reshape(ref.shape))
                prog("measure", int(vs[-1]) + 1, n)
    finally:
        prog.close()
    return acc.report()


def _write_set(a, codec, lf, opts, out: Path, t0: float) -> int:
    """An encode that writes a set of files (``train --tiles K``: OUT.json + one .lfc per tile)."""
    prog = Progress(a.quiet)
    try:
        report = codec.encode_set(lf, opts, out, prog)
    finally:
        prog.close()
    report = {"file": str(out), "encode_s": round(time.perf_counter() - t0, 3), "views": lf.rows * lf.cols,
              "codec": codec.codec_id, **report}
    notes = []
    if report.get("psnr_heldout", np.inf) < report.get("psnr_heldout_nearest_view", -np.inf):
        notes.append(f"held-out views: the set ({report['psnr_heldout']:.2f} dB) is below the nearest training "
                     f"view ({report['psnr_heldout_nearest_view']:.2f} dB); train longer (--steps) or larger")
    report["notes"] = notes
    for m in notes:
        print(f"lfcodec: warning: {m}", file=sys.stderr)
    if a.json:
        print(dump_json(report))
    elif not a.quiet:
        quality = ("" if report.get("psnr_heldout") is None else
                   f", held-out PSNR {report['psnr_heldout']:.2f} dB on {report['heldout_views']} views (nearest "
                   f"training view {report['psnr_heldout_nearest_view']:.2f} dB)")
        print(f"wrote {out} and {len(report['files']) - 1} files beside it: {report['bytes']} bytes in all"
              f"{quality}, {report['encode_s']:.1f} s")
    return 0


def cmd_train(a) -> int:
    return cmd_encode(a, "lfn")


def _warps_note(wr: dict) -> str:
    """The encode report's note on ``--warps`` (its ``warps`` entry: stored, or why not)."""
    px = wr.get("largest_correction_px")
    if "reason" in wr:
        return f"--warps: {wr['reason']}; no warps were stored"
    if wr.get("applied"):
        return (f"--warps: each view's warp is stored ({wr.get('warp_bytes')} bytes; the largest correction moves a "
                f"corner by {px:g} px) and the predictions sample through them")
    if wr.get("error_drop") is not None:
        return (f"--warps: the warps would take only {100 * wr['error_drop']:.0f}% of the prediction error away (a "
                f"corner moves by {px:g} px); no warps were stored")
    from .rectify import MIN_CORRECTION_PX

    return (f"--warps: the views are rectified already (no pixel would move by {MIN_CORRECTION_PX:g} px or more: "
            f"{px:g} px); no warps were stored")
