"""The ``lfcodec`` command line: a thin ``main(argv) -> int`` over the library.

Codecs are found through :mod:`formats.registry`; each adds its own options. Errors in input
become one line on stderr and exit code 2. This module holds the parser, ``info``, ``serve`` and
``view``; the other commands are :mod:`formats.cli_encode` (``encode``, ``train``),
:mod:`formats.cli_decode` and :mod:`formats.cli_render`, their checks :mod:`formats.cli_checks`
and their output :mod:`formats.cli_output`.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
from pathlib import Path

from . import __version__
from .codec_api import is_real
from .errors import LfcError, ParameterError, TruncatedError
from .cli_checks import is_set
from .cli_decode import cmd_decode
from .cli_encode import cmd_encode, cmd_train
from .cli_render import cmd_render


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


# -- serve, view ----------------------------------------------------------------------------
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


def _add_codec_groups(parser, only: str | None = None) -> dict:
    """Each registered codec's options in its own group (or codec ``only``'s) → {codec id:
    option dests}."""
    from .registry import available_codecs, get_codec

    groups = {}
    for cid in [only] if only is not None else available_codecs():
        codec = get_codec(cid)
        g = parser.add_argument_group(f"{cid} options", codec.description)
        before = {x.dest for x in parser._actions}
        codec.add_arguments(g)
        groups[cid] = {x.dest for x in parser._actions} - before
    return groups


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


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The command line's parser; with ``command``, only that command's parser has its codecs'
    options (the others' would load every codec plug-in for nothing: :func:`main` passes the
    command it was given)."""
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
    e.set_defaults(func=cmd_encode, _groups=_add_codec_groups(e) if command in (None, "encode") else {})

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
    t.set_defaults(func=cmd_train, _groups=_add_codec_groups(t, only="lfn") if command in (None, "train") else {},
                   target_psnr=None, target_bpp=None, min_view_psnr=None, lossless=False)
    return p


def main(argv: list[str] | None = None) -> int:
    from .heap import keep_freed, limit_arenas

    limit_arenas(1)                  # one malloc arena for the coding threads (formats.heap)
    args = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(next((x for x in args if not x.startswith("-")), None))
    a = parser.parse_args(args)
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
