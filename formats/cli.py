"""The ``lfcodec`` command line: a thin ``main(argv) -> int`` over the library.

Codecs are found through :mod:`formats.registry`; each adds its own options. Errors in input
become one line on stderr and exit code 2.
"""
from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

from . import __version__
from .codec_api import is_real
from .errors import LfcError, ParameterError, TruncatedError
from .imageio import check_parent_folder
from .cli_checks import (check_out_file, grid, ints, is_set, refuse_input_overwrite,
                         refuse_output_over_input, save_npy)
from .cli_render import cmd_render


class _Stderr:
    """Whatever ``sys.stderr`` is at the time of each write (a bar outlives the stream that
    :func:`formats.imageio.native_stderr` swaps in while image files are decoded)."""

    def write(self, text):
        return sys.stderr.write(text)

    def flush(self):
        sys.stderr.flush()

    @property
    def encoding(self):
        return getattr(sys.stderr, "encoding", None) or "utf-8"

    def isatty(self):
        try:
            return sys.stderr.isatty()
        except (AttributeError, ValueError):
            return False


class _Progress:
    """tqdm bars named by stage (one bar per stage), on stderr when it is a terminal, off with --quiet."""

    def __init__(self, quiet: bool):
        self.quiet, self.bar, self.stage = quiet, None, None

    def __call__(self, stage: str, done: int, total: int | None) -> None:
        if self.quiet:
            return
        from tqdm import tqdm

        if stage != self.stage:
            self.close()
            self.stage = stage
            # bars on a terminal only (disable=None): logs and pipes get the result lines alone
            self.bar = tqdm(total=total, desc=stage, file=_Stderr(), leave=False, disable=None)
        elif done < self.bar.n:                 # the stage again (a new rate-control pass): a fresh bar
            self.bar.reset(total=total)
        self.bar.n = done
        self.bar.refresh()

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None


def _finite(obj):
    """A JSON-able tree with every non-finite float replaced by None (exactness is reported apart)."""
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    if isinstance(obj, (float, np.floating)):
        return float(obj) if np.isfinite(obj) else None
    if isinstance(obj, np.integer):
        return int(obj)
    return obj


def _dump(obj) -> str:
    """Strict JSON (no NaN/Infinity)."""
    return json.dumps(_finite(obj), allow_nan=False)


# -- info ------------------------------------------------------------------------------------
def cmd_info(a) -> int:
    from .lfcfile import open_lfc
    from .registry import describe, open_set

    if is_set(a.file):             # a set of files (an LFN tile set's manifest): what its codec says
        if a.verify:
            raise ParameterError(f"{a.file}: --verify checks one .lfc file; verify each file the manifest names")
        with open_set(a.file, partial=a.partial) as d:
            out = {"file": str(a.file), **d.info()}
        print(json.dumps(out, indent=1, allow_nan=False) if a.json else f"{a.file}: {out['summary']}")
        return 0
    with open_lfc(a.file, partial=a.partial) as f:
        if a.verify:
            f.container.verify_all()
        c = f.container
        meta = f.meta
        scene = meta.get("scene", {})
        out = {
            "file": str(a.file), "bytes": c.size, "format_version": "%d.%d" % c.version, "codec": meta.get("codec"),
            "codec_version": meta.get("codec_version"), "encoder": meta.get("encoder"),
            "scene": {k: scene.get(k) for k in ("rows", "cols", "height", "width", "channels", "dtype", "layout",
                                                "focal")},
            "sections": [{"name": s.name, "offset": s.offset, "bytes": s.length, "chunks": s.n_chunks,
                          "available": c.available_bytes(s.name)} for s in c.sections.values()],
            "verified": bool(a.verify),
        }
        if all(isinstance(scene.get(k), int) and scene[k] > 0 for k in ("rows", "cols", "height", "width")):
            out["bpp"] = 8.0 * c.size / (scene["rows"] * scene["cols"] * scene["height"] * scene["width"])
        rect = meta.get("source", {}).get("rectified") if isinstance(meta.get("source"), dict) else None
        px = rect.get("largest_correction_px") if isinstance(rect, dict) else None
        if is_real(px) and math.isfinite(px) and px >= 0:     # (encode --rectify; informative, checked)
            out["rectified"] = {"largest_correction_px": float(px)}
        try:
            out["decoder"] = describe(f)
        except TruncatedError as e:
            if not a.partial:
                raise
            # a prefix the codec cannot open (an RLFC file needs every section): the sections
            # above are still what the prefix holds
            out["decoder"] = {"summary": f"this prefix does not open as a light field: {e}", "decodable": False}
    if a.json:
        print(json.dumps(out, indent=1, allow_nan=False))
        return 0
    s = out["scene"]
    print(f"{out['file']}: {out['bytes']} bytes, .lfc {out['format_version']}, codec {out['codec']} "
          f"v{out['codec_version']}, {out['encoder']}")
    print(f"scene: {s['rows']}x{s['cols']} views of {s['height']}x{s['width']} (HxW) x{s['channels']} {s['dtype']} "
          f"({s['layout']})" + (f", {out['bpp']:.4f} bpp" if "bpp" in out else ""))
    print(out["decoder"].get("summary", ""))
    if "rectified" in out:
        print(f"rectified when encoded (--rectify): the views are the rectified ones (the largest correction moved "
              f"a corner by {out['rectified']['largest_correction_px']:g} px)")
    print("sections:")
    for sec in out["sections"]:
        have = "" if sec["available"] == sec["bytes"] else f"  ({sec['available']} in this prefix)"
        print(f"  {sec['name']:<16} offset {sec['offset']:>10}  {sec['bytes']:>10} bytes  {sec['chunks']} chunk(s)"
              f"{have}")
    if a.verify:
        print("all checksums OK")
    return 0


# -- encode ----------------------------------------------------------------------------------
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
    prog = _Progress(a.quiet)
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
    prog = _Progress(a.quiet)
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
        print(_dump(report))
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
    prog = _Progress(quiet)
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
    prog = _Progress(a.quiet)
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
        print(_dump(report))
    elif not a.quiet:
        quality = ("" if report.get("psnr_heldout") is None else
                   f", held-out PSNR {report['psnr_heldout']:.2f} dB on {report['heldout_views']} views (nearest "
                   f"training view {report['psnr_heldout_nearest_view']:.2f} dB)")
        print(f"wrote {out} and {len(report['files']) - 1} files beside it: {report['bytes']} bytes in all"
              f"{quality}, {report['encode_s']:.1f} s")
    return 0


def cmd_train(a) -> int:
    return cmd_encode(a, "lfn")


# -- decode ----------------------------------------------------------------------------------
def cmd_serve(a) -> int:
    from .serve import FileServer

    folder = Path(a.folder)
    if not folder.is_dir():
        raise ParameterError(f"{folder}: not a folder")
    if not 0 <= a.port <= 65535 or not 0 <= a.latency_ms <= 60000:
        raise ParameterError("--port must be 0..65535 and --latency-ms 0..60000")
    srv = FileServer(folder, a.host, a.port, a.latency_ms / 1000.0, viewer=True)
    print(f"serving {folder.resolve()} at http://{srv.host}:{srv.port}/ (byte ranges, ETags); Ctrl-C stops\n"
          f"viewer: {srv.viewer_url('FILE.lfc')}", flush=True)
    try:
        srv.serve_forever()
    finally:
        srv.httpd.server_close()
    return 0


def cmd_view(a) -> int:
    from .serve import FileServer

    path = Path(a.input)
    if not path.is_file():
        raise ParameterError(f"{path}: no such file")
    if not 0 <= a.port <= 65535:
        raise ParameterError("--port must be 0..65535")
    srv = FileServer(path.resolve().parent, a.host, a.port, viewer=True)
    url = srv.viewer_url(path.name)
    print(f"viewer of {path}: {url}\n(the page reads the file by byte ranges and decodes it in the browser; "
          "Ctrl-C stops)", flush=True)
    if a.open:
        import webbrowser

        webbrowser.open(url)
    try:
        srv.serve_forever()
    finally:
        srv.httpd.server_close()
    return 0


#: what ``decode --view ROW,COL --out FILE`` writes: formats that keep every channel and bit depth
#: (a JPEG, say, would turn a 16-bit grey + alpha view into 8-bit colour without a word)
VIEW_SUFFIXES = (".png", ".tif", ".tiff", ".npy")
#: names that stand for one file, not a folder, as decode's OUTDIR with --view or --block
FILE_SUFFIXES = VIEW_SUFFIXES + (".exr", ".jpg", ".jpeg", ".bmp", ".webp", ".gif", ".jp2", ".j2k", ".jxl", ".ppm")


def _one_out_file(a, what: str) -> Path:
    """``--out`` of ``decode --view`` / ``--block``, checked before decoding: a lossless suffix (a
    .npy array written under the name b.png fooled every image viewer), not the input, not a
    folder, its folder present."""
    out = Path(a.out)
    if out.suffix.lower() not in VIEW_SUFFIXES:
        raise ParameterError(f"{out}: {what} --out writes {', '.join(VIEW_SUFFIXES)} (lossless, every channel "
                             f"and bit depth kept)")
    refuse_output_over_input(a.input, out)
    check_out_file(out)
    return out


def _write_one(out: Path, arr: np.ndarray) -> None:
    """One decoded view or block to ``out``: a .npy array, else a lossless image."""
    if out.suffix.lower() == ".npy":
        save_npy(out, arr)
    else:
        from .imageio import write_image

        write_image(out, arr)


def _kept_outputs(d, outdir: Path, name, views: list, level, layouts: list, overwrite: bool) -> set:
    """Files in ``outdir`` that a decode of ``views`` [(row, col)] would replace: the (row, col)
    whose file already holds exactly the decoded pixels (left as they are: a decode run again);
    any other file there (a capture's own images, a decode at another level, a layout file
    lfcodec did not write) is a ParameterError unless ``overwrite``."""
    from .imageio import read_image
    from .scenes.layout import written_by_lfcodec
    from .viewnames import output_path

    same: set = set()
    if overwrite or not outdir.is_dir():
        return same
    for p in layouts:
        if p.exists() and not written_by_lfcodec(p):
            raise ParameterError(f"{p}: exists and is not a layout file lfcodec wrote; decode to another folder, or "
                                 f"give --overwrite to replace the files there")
    for r, c in views:
        p = output_path(outdir, name(r, c))
        if not p.exists():
            continue
        try:                          # (an image larger than a view is not it: never decoded)
            old = read_image(p, max_pixels=d.height * d.width)
        except LfcError:
            old = None
        new = d.decode_view(r, c, level=level)
        if old is None or old.size != new.size or not np.array_equal(old.reshape(new.shape), new):
            raise ParameterError(f"{p}: exists and is not this view as decoded here; decode to another folder, or "
                                 f"give --overwrite to replace the files there")
        same.add((r, c))
    return same


def cmd_decode(a) -> int:
    try:
        return _decode(a)
    except TruncatedError as e:
        if a.partial and "meta.more" in str(e):     # an LFN prefix: its captured cameras come last
            raise TruncatedError(f"{e}: the captured views need their cameras; render this prefix at a camera "
                                 f"instead (lfcodec render --partial --pose FILE)") from None
        raise


@contextlib.contextmanager
def _decode_source(a):
    """(the capture's geometry, its opened decoder) for ``decode``'s input: an .lfc file, or a
    set of files (an LFN tile set's manifest: its views rendered by the blend). Closed on exit."""
    from .lfcfile import open_lfc
    from .registry import open_decoder, open_set

    if is_set(a.input):
        with open_set(a.input, partial=a.partial) as d:
            yield d.scene, d
        return
    with open_lfc(a.input, partial=a.partial) as f:
        yield f.scene, open_decoder(f)


def _decode(a) -> int:
    from concurrent.futures import ThreadPoolExecutor

    from .parallel import LOCAL_THREADS
    from .scenes import view_filename, write_layout, write_views
    from .scenes.layout import layout_paths
    from .viewnames import output_path, png_name, unpack_names

    if (a.block is not None or a.view is not None) and a.out is None and a.outdir is not None \
            and Path(a.outdir).suffix.lower() in FILE_SUFFIXES and not Path(a.outdir).is_dir():
        a.out, a.outdir = a.outdir, None         # `decode IN one.png --view R,C`: a file, not a folder named so
    if a.block is not None and a.out is None:
        raise ParameterError("--block needs --out FILE (.npy, .png, .tif or .tiff)")
    if a.out is not None and a.outdir is not None:
        raise ParameterError("give an output folder (OUTDIR) or --out FILE, not both")
    if a.out is not None and a.block is None and a.view is None:
        raise ParameterError("--out FILE goes with --view ROW,COL (one view) or --block ROW,COL,BY,BX; all views "
                             "go to an output folder (OUTDIR)")
    if a.block is None and a.outdir is None and a.out is None:
        raise ParameterError("give an output folder (OUTDIR), or --view ROW,COL / --block ROW,COL,BY,BX with "
                             "--out FILE")
    level = a.level
    if not math.isfinite(level) or level < 0:
        raise ParameterError(f"--level must be a finite number >= 0, got {level}")
    if level == int(level):
        level = int(level)
    with _decode_source(a) as (scene, d):
        t0 = time.perf_counter()
        if a.block is not None:
            r, c, by, bx = ints(a.block, 4, "--block")
            out = _one_out_file(a, "--block")
            blk = d.decode_block(r, c, by, bx, level=level)
            _write_one(out, blk)
            if not a.quiet:
                print(f"wrote {out}: block ({by},{bx}) of view ({r},{c}), shape {blk.shape} {blk.dtype}, "
                      f"level {a.level:g}, {1e3 * (time.perf_counter() - t0):.2f} ms")
            return 0
        if a.out is not None:                    # one view to one file: an image, or .npy
            out = _one_out_file(a, "--view")
            r, c = ints(a.view, 2, "--view")
            img = d.decode_view(r, c, level=level)
            _write_one(out, img)
            if not a.quiet:
                print(f"wrote {out}: view ({r},{c}), shape {img.shape} {img.dtype}, level {a.level:g}, "
                      f"{time.perf_counter() - t0:.2f} s")
            return 0
        outdir = Path(a.outdir)
        if outdir.exists() and not outdir.is_dir():
            raise ParameterError(f"{outdir}: exists and is not a folder")
        if not outdir.exists():                  # as encode: no folders made on the way
            check_parent_folder(outdir)
        layout = None
        name = view_filename
        if a.names == "original":
            if not isinstance(scene, dict) or "names_z" not in scene:
                raise ParameterError(f"{a.input}: the file does not record its views' original names (encoded "
                                     f"from an array or by an older lfcodec); decode without --names original")
            orig = unpack_names(scene["names_z"], d.rows * d.cols, f"{a.input}: scene names_z")

            def name(r, c):
                return png_name(orig[r * d.cols + c])
        if a.view is not None:
            r, c = ints(a.view, 2, "--view")
            if (r, c) in _kept_outputs(d, outdir, name, [(r, c)], level, [], a.overwrite):
                paths = [output_path(outdir, name(r, c))]
            else:
                img = d.decode_view(r, c, level=level)
                paths = write_views(outdir, img[None, None], rows=[r], cols=[c], filename=name)
        else:
            keep = _kept_outputs(d, outdir, name, [(r, c) for r in range(d.rows) for c in range(d.cols)], level,
                                 layout_paths(outdir, scene), a.overwrite)
            prog = _Progress(a.quiet)
            # decoded one row of views at a time, each row's files written on a few threads while
            # the next row decodes (image encoders release the GIL): at most two rows are held
            paths, made, writing = [], [], []
            pool = ThreadPoolExecutor(LOCAL_THREADS)
            try:
                for r in range(d.rows):
                    cs = [c for c in range(d.cols) if (r, c) not in keep]
                    row = d.decode_views(np.asarray(cs, np.int64) + r * d.cols, level=level)[None] if cs else None
                    for w in writing:                      # the previous row's files are written
                        w.result()
                    writing = []
                    for j, c in enumerate(cs):
                        p = output_path(outdir, name(r, c))
                        if not p.exists():
                            made.append(p)
                        writing.append(pool.submit(write_views, outdir, row[:, j:j + 1], rows=[r], cols=[c],
                                                   filename=name))
                    paths += [output_path(outdir, name(r, c)) for c in range(d.cols)]
                    del row
                    prog("decode views", r + 1, d.rows)
                for w in writing:
                    w.result()
            except BaseException:
                # a file that fails part-way (a damaged stream in a later row) leaves none of the
                # views it made behind: a folder holding only some views would pass for a whole
                # decode (files that were there before stay)
                pool.shutdown(wait=True, cancel_futures=True)
                for p in made:
                    Path(p).unlink(missing_ok=True)
                raise
            finally:
                pool.shutdown(wait=True)
                prog.close()
            # the layout file, so that the folder encodes again as the same scene
            layout = write_layout(outdir, scene, name)
        if not a.quiet:
            lname = "" if layout is None else f" and {'transforms_*.json' if layout.name.startswith('transforms_') else layout.name}"
            print(f"wrote {len(paths)} view(s){lname} to {outdir} (level "
                  f"{a.level:g}) in {time.perf_counter() - t0:.2f} s")
    return 0


# -- parser ----------------------------------------------------------------------------------
def _add_codec_groups(parser, only: str | None = None) -> dict:
    """Each registered codec's options in its own group → {codec id: option dests}."""
    from .registry import available_codecs, get_codec

    groups = {}
    for cid in available_codecs():
        if only is not None and cid != only:
            continue
        codec = get_codec(cid)
        g = parser.add_argument_group(f"{cid} options", codec.description)
        before = {x.dest for x in parser._actions}
        codec.add_arguments(g)
        groups[cid] = {x.dest for x in parser._actions} - before
    return groups


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


def _add_scene_options(e) -> None:
    e.add_argument("--baseline", type=float, default=None, help="grid baseline when the scene has none")
    e.add_argument("--focal", type=float, default=None, help="focal length in pixels when the scene has none")
    e.add_argument("--split", default="train", help="transforms_<split>.json to read (default train; all = every "
                                                    "split as one capture, written back split by split on decode)")
    e.add_argument("--grid", metavar="ROWSxCOLS", default=None,
                   help="read a plain folder of images as this grid (natural name order, row-major)")
    e.add_argument("--allow-outside-paths", action="store_true",
                   help="read view files that lie outside the scene folder (refused by default)")
    e.add_argument("--rectify", action="store_true",
                   help="grids: estimate each view's rotation, scale and shift from the views (a rig that is not "
                        "rectified) and resample the views onto the rectified grid before coding; the file holds "
                        "the rectified views and PSNRs are against them (nothing is changed where no pixel would "
                        "move by 0.5 px)")
    e.add_argument("--json", action="store_true", help="print one JSON object (bytes, bpp, PSNRs, SSIM, times)")
    e.add_argument("--quiet", action="store_true", help="no progress bars or messages")


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors: a bad value prints ``lfcodec CMD: error: …`` and exits with
    2, without the usage block (``--help`` shows it); sub-commands' parsers are of this class."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="lfcodec", description="Light-field compression: encode, decode and inspect .lfc files.")
    p.add_argument("--version", action="version", version=f"lfcodec {__version__}")
    sub = p.add_subparsers(dest="cmd", required=True)

    i = sub.add_parser("info", help="show an .lfc file's sections, sizes, codec and scene geometry",
                       description="Show an .lfc file's sections, sizes, codec and scene geometry.")
    i.add_argument("file")
    i.add_argument("--json", action="store_true", help="print one JSON object")
    i.add_argument("--verify", action="store_true", help="check every checksum of every section")
    i.add_argument("--partial", action="store_true", help="accept a byte prefix of a file and show what it holds")
    i.set_defaults(func=cmd_info)

    e = sub.add_parser("encode", help="encode a scene folder to an .lfc file",
                       description="Encode a light field (grid scene, HCI/Stanford folder, LLFF capture or "
                                   "transforms.json) to an .lfc file.")
    e.add_argument("scene", help="scene folder, transforms*.json, or an .npy array of views (N,H,W[,C]) with --grid")
    e.add_argument("out", help="output .lfc file (replaced atomically)")
    e.add_argument("--codec", default="rlfc", help="codec id (default rlfc; lfn trains a light field network)")
    g = e.add_mutually_exclusive_group()
    g.add_argument("--target-psnr", type=float, default=None, metavar="DB",
                   help="smallest file with colour PSNR >= DB (pooled over all views)")
    g.add_argument("--target-bpp", type=float, default=None, metavar="X", help="best quality with bpp <= X")
    g.add_argument("--lossless", action="store_true", help="bit-exact decode")
    e.add_argument("--min-view-psnr", type=float, default=None, metavar="DB",
                   help="every view at least DB: the tx profile raises the pooled PSNR target until the worst view "
                        "meets it (other profiles and --target-bpp: reported only); warns when a view does not")
    e.add_argument("--workers", type=int, default=1, metavar="N",
                   help="code views on N local worker processes (default 1; the file is the same for any N)")
    e.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="code views on a dask.distributed cluster (e.g. tcp://host:8786) instead")
    _add_scene_options(e)
    e.set_defaults(func=cmd_encode, _groups=_add_codec_groups(e))

    d = sub.add_parser("decode", help="decode views, one view, or one block of an .lfc file",
                       description="Decode an .lfc file: all views as PNG (rRR_cCC.png), one view (--view; into OUTDIR, "
                                   "or to --out FILE.png / .npy), or one pixel block of one view (--block "
                                   "ROW,COL,BY,BX --out FILE.npy).")
    d.add_argument("input")
    d.add_argument("outdir", nargs="?", help="output folder for PNG views (created if missing; its parent must exist); "
                                             "with --view or --block, a name ending .png, .tif, .tiff or .npy is "
                                             "the one file written (as --out)")
    d.add_argument("--view", metavar="ROW,COL", help="decode only this view")
    d.add_argument("--overwrite", action="store_true",
                   help="replace files in OUTDIR that are not the decoded views already (by default a decode "
                        "leaves such files alone and stops: e.g. a capture's own images, under --names original)")
    d.add_argument("--block", metavar="ROW,COL,BY,BX",
                   help="decode one block: view (ROW,COL), block row BY and column BX (pixels [BY*B,(BY+1)*B) x "
                        "[BX*B,(BX+1)*B))")
    d.add_argument("--out", metavar="FILE", help="where --block writes its (B, B, C) block or --view its (H, W, C) "
                                                 "view: .npy, or a lossless .png / .tif image")
    d.add_argument("--level", type=float, default=0,
                   help="0 = full quality (default); larger = coarser, up to the file's levels (lfcodec info)")
    d.add_argument("--names", choices=("grid", "original"), default="grid",
                   help="file names of decoded views: grid = rRR_cCC.png (default); original = the names the "
                        "views had when encoded, as PNG (subfolders kept, e.g. images/IMG_0001.png)")
    d.add_argument("--partial", action="store_true",
                   help="accept a byte prefix of a file (a progressive download): use what its bytes hold (a light field "
                        "network's prefix is a smaller network; its captured cameras are at the end, so a prefix "
                        "without them renders at a camera you give: lfcodec render --partial --pose)")
    d.add_argument("--quiet", action="store_true", help="no progress bars or messages")
    d.set_defaults(func=cmd_decode)

    r = sub.add_parser("render", help="render a novel view (or a refocused view, or a quilt) from an .lfc file",
                       description="RLFC grids: render the view at a continuous grid position by disparity-"
                                   "compensated interpolation of the decoded views around it, decoding only the "
                                   "blocks the frame needs. Light field networks: render any camera (--at, --pose, "
                                   "--turn, --stereo) at any level, from the whole file or a prefix of it. IN.lfc "
                                   "may be a URL.")
    r.add_argument("input")
    r.add_argument("out", help="output PNG")
    r.add_argument("--at", metavar="S,T", default=None,
                   help="camera position: row S and column T in view units (view (r,c) is at r,c); default the "
                        "grid centre (for a light field network the captured view nearest it; between views, the "
                        "network's camera centres are blended: meaningful on grids and ordered camera paths)")
    r.add_argument("--focus", type=float, default=None,
                   help="disparity in px per view step to focus on (default: the file's disparity maps)")
    r.add_argument("--aperture", type=float, default=0.0,
                   help="synthetic-aperture radius in view steps (0 = pinhole; >0 refocuses at --focus)")
    r.add_argument("--quilt", metavar="COLSxROWS", default=None,
                   help="write a quilt of COLS*ROWS views for light-field displays, bottom-left first: an RLFC "
                        "grid's views along its middle row; a light field network's camera (--at, --pose) turned "
                        "across a 35 degree view cone about the scene")
    r.add_argument("--path", metavar="SPEC", default=None,
                   help="render a sequence along a camera path: orbit[:N], sweep[:N] (N frames, default 60) or a "
                        "file of cameras 's,t[,focus[,aperture]]' per line; for light field networks also turn[:N] "
                        "(the --at/--pose camera turned a full circle about the scene); OUT is then a folder (PNG "
                        "frames) or an .mp4 (ffmpeg)")
    r.add_argument("--fps", type=float, default=30.0, help="frame rate of an --path MP4 (default 30)")
    r.add_argument("--overwrite", action="store_true",
                   help="--path into a folder that holds frames already: replace them (and remove the earlier "
                        "sequence's frames past the new one's end); refused without it")
    r.add_argument("--fast", action="store_true",
                   help="RLFC grids: use the file's disparity maps as they are (about 3x faster; the default also "
                        "tries smoother disparities where the maps make the views disagree, e.g. on noisy "
                        "captures). Light field networks: where the frame is finer than the network was trained "
                        "at, run it on its own pixel grid and upsample (3-5x faster, within 0.05 dB)")
    r.add_argument("--device", default="auto",
                   help="where the pixels are computed: auto (a CUDA GPU through torch when present, else numpy; "
                        "default), numpy, or a torch device (cuda, cuda:1, cpu); the frames agree within rounding")
    r.add_argument("--pose", metavar="FILE", default=None,
                   help="light field networks: the camera as a 4x4 camera-to-world matrix (OpenGL axes, scene "
                        "units) in a file: JSON (a list of 4 rows, or a transforms.json frame) or 16 numbers")
    r.add_argument("--turn", metavar="YAW[,PITCH]", default=None,
                   help="light field networks: turn the camera (--at, --pose) about the scene's pivot by YAW "
                        "degrees about the up axis and PITCH about its right axis")
    r.add_argument("--stereo", metavar="IPD", type=float, default=None,
                   help="light field networks: a side-by-side left|right pair, eyes IPD scene units apart")
    r.add_argument("--level", type=float, default=None,
                   help="light field networks: 0 = the largest network in the file's bytes; larger = fewer "
                        "neurons, up to the file's levels (lfcodec info); default: the largest size of the file's "
                        "display ladder within its bytes (sizes the encoder measured to beat every smaller one)")
    r.add_argument("--scale", type=float, default=None,
                   help="light field networks: output size relative to the captured views, (0, 4] (default 1)")
    r.add_argument("--gaze", metavar="X,Y", default=None,
                   help="light field networks: foveated rendering around this point (pixels of the output frame): "
                        "the largest network near it, smaller networks drawn with fewer samples farther out "
                        "(about half a full render's time)")
    r.add_argument("--fovea", metavar="INNER,OUTER", default=None,
                   help="with --gaze: the full network within INNER x the frame's diagonal of the gaze, the base "
                        "network from OUTER x the diagonal on (default 0.1,0.5)")
    r.add_argument("--partial", action="store_true",
                   help="accept a byte prefix of a file (a progressive download): use what its bytes hold (a light field "
                        "network's prefix is a smaller network; its captured cameras are at the end, so give --pose)")
    r.add_argument("--quiet", action="store_true", help="no progress bars or messages")
    r.set_defaults(func=cmd_render)

    v = sub.add_parser("serve", help="serve a folder over HTTP with byte ranges (for remote reading)",
                       description="Serve the files of a folder over HTTP with byte ranges and ETags, so that "
                                   "lfcodec (or a browser) can read .lfc files remotely: lfcodec info "
                                   "http://HOST:PORT/file.lfc. Local use and tests; not a production server.")
    v.add_argument("folder")
    v.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1)")
    v.add_argument("--port", type=int, default=8000, help="port (default 8000; 0 = any free port)")
    v.add_argument("--latency-ms", type=float, default=0.0, help="delay every answer, to stand for a network")
    v.set_defaults(func=cmd_serve)

    w = sub.add_parser("view", help="open an .lfc file in the browser viewer (a local server; prints the URL)",
                       description="Serve IN.lfc's folder on a local port with the browser viewer and print the "
                                   "page's URL. The page fetches the file by HTTP Range requests and decodes it in "
                                   "the browser (RLFC profile tx: key views, maps, residual blocks; JPEG 2000 key "
                                   "views through OpenJPEG compiled to WebAssembly); drag to move the viewpoint, "
                                   "sliders for focus and aperture. Light field networks and LFN tile sets (their "
                                   "manifest, OUT.json) render in the page as well.")
    w.add_argument("input", help="an .lfc file, or an LFN tile set's manifest (.json)")
    w.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1)")
    w.add_argument("--port", type=int, default=8000, help="port (default 8000; 0 = any free port)")
    w.add_argument("--open", action="store_true", help="also open the page in the default browser")
    w.set_defaults(func=cmd_view)

    t = sub.add_parser("train", help="train a light field network (same as encode --codec lfn)",
                       description="Train a nested-width light field network with continuous levels of detail and "
                                   "write it as an .lfc stream (any prefix of which is a smaller network).")
    t.add_argument("scene")
    t.add_argument("out")
    _add_scene_options(t)
    t.set_defaults(func=cmd_train, _groups=_add_codec_groups(t, only="lfn"), target_psnr=None, target_bpp=None,
                   min_view_psnr=None, lossless=False)
    return p


def main(argv: list[str] | None = None) -> int:
    from .heap import keep_freed, limit_arenas

    limit_arenas(1)                  # one malloc arena for the coding threads (formats.heap)
    parser = build_parser()
    a = parser.parse_args(argv)
    if getattr(a, "func", None) is cmd_render:
        keep_freed()                 # frame after frame: freed blocks reused, not faulted in again
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
