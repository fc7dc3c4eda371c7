"""``lfcodec decode``: every view, one view or one block of a file (or of an LFN tile set) to
images or arrays, never over the input or over files it did not write (:func:`cmd_decode`)."""
from __future__ import annotations

import contextlib
import math
import time
from pathlib import Path

import numpy as np

from .cli_checks import (FILE_SUFFIXES, VIEW_SUFFIXES, check_out_file, ints, is_set, refuse_output_over_input,
                         save_npy)
from .cli_output import Progress
from .errors import LfcError, ParameterError, TruncatedError
from .imageio import check_parent_folder

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
            prog = Progress(a.quiet)
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
