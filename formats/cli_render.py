"""``lfcodec render``: a novel view, a refocused view, a quilt or a camera path from an .lfc
file (RLFC light fields through :class:`rlfc.render.Renderer`, light field networks through
:mod:`lfn_stream`), written as images, an image folder or a video."""
from __future__ import annotations

import contextlib
import math
import sys
import time
from pathlib import Path

import numpy as np

from .errors import ParameterError, TruncatedError
from .cli_checks import check_out_file, floats, grid, is_set, refuse_output_over_input


def cmd_render(a) -> int:
    from .campath import turn_frames
    from .imageio import write_image

    out = Path(a.out)
    refuse_output_over_input(a.input, out)
    if a.path is not None:
        turn = turn_frames(a.path) is not None
        if a.quilt or a.turn is not None or (not turn and (a.at is not None or a.pose is not None)):
            raise ParameterError("--path renders a sequence: it does not go with --quilt or --turn, nor with --at or "
                                 "--pose (except --path turn, which turns that camera)")
        return _render_path(a, out)
    if not (math.isfinite(a.fps) and 0 < a.fps <= 1000):
        raise ParameterError(f"--fps must be within (0, 1000], got {a.fps}")
    if out.suffix.lower() != ".png":
        raise ParameterError(f"{out}: render writes PNG files (name it .png; a folder or .mp4 with --path)")
    check_out_file(out)
    with _render_source(a) as (lfn, d):
        if lfn:
            return _render_lfn_still(a, d, out)
        ren = _grid_renderer(a, d)
        t0 = time.perf_counter()
        if a.quilt:
            cols, rows = grid(a.quilt)
            img = ren.quilt(cols, rows, a.focus)
        else:
            s, t = floats(a.at, 2, "--at") if a.at else ((d.rows - 1) / 2, (d.cols - 1) / 2)
            img = ren.render(s, t, a.focus, a.aperture)
        write_image(out, img)
        if not a.quiet:
            print(f"wrote {out} ({img.shape[1]}x{img.shape[0]} px, WxH) in {time.perf_counter() - t0:.2f} s, "
                  f"{ren.blocks_decoded} blocks decoded")
    return 0


QUILT_CONE = 35.0   # degrees: a light field network's quilt turns the camera across this view cone


@contextlib.contextmanager
def _render_source(a):
    """(is a light field network, its opened decoder) for ``render``'s input: a set of files (an
    LFN tile set's manifest, opened by its codec) or an .lfc file; options that do not apply to
    the kind are refused (:func:`_render_kind`). Closed on exit."""
    from .lfcfile import open_lfc
    from .registry import open_decoder, open_set

    if is_set(a.input):
        _render_kind(a, "lfn")
        with open_set(a.input, device=_lfn_device(a.device), partial=a.partial) as d:
            yield True, d
        return
    with open_lfc(a.input, partial=a.partial) as f:
        lfn = _render_kind(a, f.codec)
        yield lfn, (open_decoder(f, device=_lfn_device(a.device)) if lfn else open_decoder(f))


def _render_lfn_still(a, d, out: Path) -> int:
    """One frame (or a quilt) from a light field network or a tile set of them."""
    from .campath import assemble_quilt, quilt_views
    from .imageio import write_image

    t0 = time.perf_counter()
    if a.quilt:
        cols, rows = grid(a.quilt)
        if a.stereo is not None:
            raise ParameterError("--quilt and --stereo are two different layouts: give one")
        base, n = _lfn_camera(a, d), quilt_views(cols, rows)
        yaws = np.linspace(-QUILT_CONE / 2, QUILT_CONE / 2, n) if n > 1 else np.zeros(1)
        img = assemble_quilt([_lfn_frame(a, d, d.turn_pose(base, float(y))) for y in yaws], cols, rows)
    else:
        img = _lfn_frame(a, d, _lfn_camera(a, d))
    write_image(out, img)
    if not a.quiet:
        print(f"wrote {out} ({img.shape[1]}x{img.shape[0]} px, WxH) in {time.perf_counter() - t0:.2f} s, "
              f"{_lfn_size_text(a, d)}, {d.rays_evaluated} rays evaluated")
    return 0


def _render_kind(a, codec: str) -> bool:
    """True for a light field network file (rendered from camera poses), False for an RLFC grid
    (rendered from decoded views); options that do not apply to the file's kind are refused."""
    from .campath import turn_frames

    lfn = codec == "lfn"
    if a.fovea is not None and a.gaze is None:
        raise ParameterError("--fovea sets the radii of --gaze's foveation: give --gaze X,Y too")
    if lfn:
        used = [o for o, v in (("--focus", a.focus is not None), ("--aperture", a.aperture != 0)) if v]
        if used:
            raise ParameterError(f"{a.input}: {', '.join(used)} refocus an RLFC grid from its disparity maps; a light "
                                 f"field network renders pinhole cameras (--at, --pose, --turn, --stereo)")
    else:
        used = [o for o, v in (("--pose", a.pose), ("--turn", a.turn), ("--stereo", a.stereo), ("--level", a.level),
                               ("--scale", a.scale), ("--gaze", a.gaze)) if v is not None]
        if used:
            raise ParameterError(f"{a.input}: {', '.join(used)} {'is an option' if len(used) == 1 else 'are options'} "
                                 f"for light field network files (this is {codec}); an RLFC grid renders positions "
                                 f"on its camera plane (--at)")
        if a.path is not None and turn_frames(a.path) is not None:
            raise ParameterError(f"{a.input}: --path turn turns a free camera about the scene, which light field "
                                 f"network files render; an RLFC grid takes orbit, sweep or a file of cameras")
    return lfn


def _grid_renderer(a, d):
    """The novel-view renderer of an opened grid decoder (ParameterError for codecs without one)."""
    if not hasattr(d, "renderer"):
        raise ParameterError(f"{a.input}: this codec ({d.info().get('codec')}) cannot render novel views")
    return d.renderer(robust=not a.fast, device=a.device)


def _lfn_device(device: str) -> str | None:
    """--device for a light field network: a torch device (auto = CUDA when present; numpy = cpu)."""
    if device == "auto":
        return None
    if device == "numpy":
        return "cpu"
    import torch

    try:
        dev = torch.device(device)
    except (RuntimeError, TypeError, ValueError):
        raise ParameterError(f"--device {device!r}: not a device (auto, numpy, cpu, cuda, cuda:1)") from None
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise ParameterError(f"--device {device}: no CUDA GPU is usable here")
    if dev.type not in ("cpu", "cuda"):
        raise ParameterError(f"--device {device}: light field networks render on cpu or cuda")
    return device


def _lfn_neurons(a, d) -> float:
    """Neurons per layer of the network --level asks for (absent: the file's display size for
    the bytes held at --scale, see LfnRenderer.display_neurons_at; 0 = the largest available)."""
    if a.level is None:
        scale = 1.0 if a.scale is None else a.scale
        return d.display_neurons_at(scale) if math.isfinite(scale) and scale > 0 else d.display_neurons
    level = a.level
    if not math.isfinite(level):
        raise ParameterError(f"--level must be a finite number, got {level}")
    return d.neurons_at(level)


def _lfn_size_text(a, d) -> str:
    """The network a render used, for its report line."""
    n = d.neurons if a.gaze else _lfn_neurons(a, d)
    k = d.native_stride(n, 1.0 if a.scale is None else a.scale) if a.fast else 1
    if a.gaze:
        return f"foveated around {a.gaze}: the network of {n:g} neurons per layer at the gaze" + (
            f", run every {k} pixels there (its own resolution)" if k > 1 else "")
    return f"network of {n:g} neurons per layer ({d.neurons:g} in the file's bytes)" + (
        f", run every {k} pixels (its own resolution) and upsampled" if k > 1 else "")


def _lfn_camera(a, d) -> np.ndarray:
    """The camera of --at / --pose (default the grid centre), turned by --turn."""
    from .campath import read_pose

    if a.at is not None and a.pose is not None:
        raise ParameterError("--at and --pose both place the camera: give one")
    turn = None
    if a.turn is not None:
        turn = floats(a.turn, a.turn.count(",") + 1, "--turn")
        if len(turn) > 2:
            raise ParameterError(f"--turn is YAW[,PITCH] in degrees, got {a.turn!r}")
    try:                                    # the captured cameras (and the pivot) may lie past a prefix
        if a.pose is not None:
            pose = read_pose(a.pose)
        elif a.at is not None:
            pose = d.grid_pose(*floats(a.at, 2, "--at"))
        else:                               # a captured camera: posed captures need not be in spatial order
            pose = d.pose(d.rows // 2, d.cols // 2)
        return pose if turn is None else d.turn_pose(pose, *turn)
    except TruncatedError as e:
        raise TruncatedError(f"{e}: a prefix renders the camera given by --pose FILE, without --turn") from None


def _lfn_frame(a, d, pose: np.ndarray) -> np.ndarray:
    """Pixels of one camera (a side-by-side left|right pair with --stereo) at --level and --scale."""
    scale = 1.0 if a.scale is None else a.scale
    if not (math.isfinite(scale) and 0 < scale <= 4):
        raise ParameterError(f"--scale must be within (0, 4], got {scale}")
    if a.fast and not hasattr(d, "native_scale"):
        raise ParameterError(f"{a.input}: --fast runs one network on its own pixel grid; a tile set blends "
                             f"several (render it without --fast)")
    if a.gaze is not None:
        render = _lfn_foveated(a, d, scale)
    else:
        neurons = _lfn_neurons(a, d)
        kw = {"native": True} if a.fast else {}
        render = lambda p: d.render_pose(p, neurons, scale, **kw)      # noqa: E731
    if a.stereo is None:
        return d.to_pixels(render(pose))
    if not (math.isfinite(a.stereo) and 0 <= a.stereo <= 1e6):
        raise ParameterError(f"--stereo is a finite eye distance >= 0 in scene units, got {a.stereo}")
    return np.concatenate([d.to_pixels(render(p)) for p in d.stereo_poses(pose, a.stereo)], axis=1)


def _lfn_foveated(a, d, scale: float):
    """``pose → RGBA`` rendering --gaze's foveation map (the largest held network inside
    --fovea's inner radius, the base network at its outer one) with fewer samples where the
    network is coarser (LfnRenderer.render_pose_lod_mip; a tile set blends its tiles' frames)."""
    if a.level is not None:
        raise ParameterError("--gaze renders the largest network at the gaze and smaller ones around it: give "
                             "--gaze or --level")
    gaze = floats(a.gaze, 2, "--gaze")
    inner, outer = floats(a.fovea or "0.1,0.5", 2, "--fovea")
    fmap = d.foveation_map(tuple(gaze), inner, outer, dither=False, scale=scale)
    kw = {"native": True} if a.fast else {}            # (a tile set refused --fast before this)
    return lambda p: d.render_pose_lod_mip(p, fmap, **kw)


def _render_path(a, out: Path) -> int:
    """``render --path``: a sequence of frames along a camera path, to PNG frames or an MP4."""
    from formats.campath import read_path

    from .video import SequenceWriter

    with _render_source(a) as (lfn, d):
        if lfn:
            return _render_lfn_path(a, d, out)
        ren = _grid_renderer(a, d)
        cams = read_path(a.path, d.rows, d.cols)
        if a.focus is not None:
            cams[:, 2] = a.focus
        if a.aperture:
            cams[:, 3] = a.aperture
        for s_, t_, foc, ap in cams.tolist():           # every camera checked before any frame is written
            ren.check_camera(s_, t_)
            ren.check_optics(None if math.isnan(foc) else foc, ap)
        times = []
        with SequenceWriter(out, a.fps, a.overwrite) as w:
            for i, (s_, t_, foc, ap) in enumerate(cams.tolist()):
                t0 = time.perf_counter()
                img = ren.render(s_, t_, None if math.isnan(foc) else foc, ap)
                times.append(time.perf_counter() - t0)
                w.write(img)
                if not a.quiet and (i + 1) % 10 == 0:
                    print(f"\r{i + 1}/{len(cams)} frames", end="", file=sys.stderr, flush=True)
        if not a.quiet:
            n = len(times)
            hit = 1 - ren.blocks_decoded / max(1, ren.blocks_requested)
            print(f"\rwrote {out}: {n} frames of {d.width}x{d.height} px (WxH); render {1e3 * times[0]:.0f} ms first frame, "
                  f"{1e3 * float(np.median(times[1:] or times)):.0f} ms median ({1 / float(np.median(times)):.1f} fps), "
                  f"{ren.blocks_decoded / n:.0f} blocks decoded per frame, cache hit rate {hit:.0%}")
    return 0


def _render_lfn_path(a, d, out: Path) -> int:
    """``render --path`` on a light field network: grid positions of orbit / sweep / a camera file
    through :meth:`grid_pose`, or ``turn[:N]``: the --at / --pose camera turned a full circle
    about the scene's pivot in N frames."""
    from formats.campath import read_path, turn_frames

    from .video import SequenceWriter

    n = turn_frames(a.path)
    if n is not None:
        base = _lfn_camera(a, d)
        poses = [d.turn_pose(base, 360.0 * i / n) for i in range(n)]
    else:
        cams = read_path(a.path, d.rows, d.cols)
        if not np.isnan(cams[:, 2]).all() or (cams[:, 3] != 0).any():
            raise ParameterError(f"{a.path}: focus and aperture refocus RLFC grids; a light field network path "
                                 f"gives positions only")
        poses = [d.grid_pose(s_, t_) for s_, t_ in cams[:, :2].tolist()]   # every camera checked first
    times = []
    with SequenceWriter(out, a.fps, a.overwrite) as w:
        for i, pose in enumerate(poses):
            t0 = time.perf_counter()
            img = _lfn_frame(a, d, pose)
            times.append(time.perf_counter() - t0)
            w.write(img)
            if not a.quiet and (i + 1) % 10 == 0:
                print(f"\r{i + 1}/{len(poses)} frames", end="", file=sys.stderr, flush=True)
    if not a.quiet:
        print(f"\rwrote {out}: {len(times)} frames of {img.shape[1]}x{img.shape[0]} px (WxH); render "
              f"{1e3 * times[0]:.0f} ms first frame, {1e3 * float(np.median(times[1:] or times)):.0f} ms median, "
              f"{_lfn_size_text(a, d)}")
    return 0
