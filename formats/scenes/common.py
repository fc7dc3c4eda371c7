"""Helpers shared by the scene readers: confining paths to the scene, bounded loading of a
list of image files into one array, and typed number parsing."""
from __future__ import annotations

import math
import os
import threading
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Callable
from pathlib import Path

import numpy as np

from ..errors import SceneError
from ..imageio import IMAGE_EXTENSIONS, image_size, native_stderr, read_image
from ..limits import DEFAULT, Limits


@dataclass(frozen=True)
class ReadOptions:
    """How a scene may be read.

    Attributes:
        limits: caps on views and pixels per view, checked before pixels are read.
        allow_outside: read files that lie outside the scene folder (``..``, absolute paths,
            symlinks leading out). Off by default: a scene file from elsewhere must not pull in
            arbitrary images from the host.
        progress: ``progress(stage, done, total)`` as views are decoded (the CLI's bars), or None.
        lazy: grid readers leave the views in their files (:class:`ImageFiles`), each decoded
            when a codec asks for it, instead of decoding them all into memory first.
    """

    limits: Limits = DEFAULT
    allow_outside: bool = False
    progress: Callable[[str, int, int], None] | None = field(default=None, compare=False)
    lazy: bool = False


NPY_MAGIC = b"\x93NUMPY"


def open_npy(p: Path, what: str) -> np.ndarray:
    """A ``.npy`` file memory-mapped read-only (nothing is read or allocated beyond its header
    until used: the caller checks the shape first), or a SceneError saying what it is instead:
    not a NumPy file, Python objects (pickled data, never loaded), or a file shorter than its
    header's shape."""
    try:
        with open(p, "rb") as f:
            head = f.read(len(NPY_MAGIC))
    except OSError as e:
        raise SceneError(f"{p}: cannot read {what} ({e.strerror or e})") from None
    if head != NPY_MAGIC:
        raise SceneError(f"{p}: not a NumPy .npy file (no NumPy header); {what} must be saved with numpy.save")
    try:
        return np.load(p, mmap_mode="r", allow_pickle=False)
    except ValueError as e:
        if "pickle" in str(e) or "bject" in str(e):
            raise SceneError(f"{p}: holds Python objects (pickled data), which lfcodec does not load; save "
                             f"{what} as a numeric array") from None
        if "mmap length" in str(e):
            raise SceneError(f"{p}: shorter than the array its .npy header describes (truncated?)") from None
        raise SceneError(f"{p}: not a readable .npy array ({e})") from None
    except (OSError, EOFError) as e:
        raise SceneError(f"{p}: not a readable .npy array ({type(e).__name__}: {e})") from None


def is_image(p: Path) -> bool:
    return p.suffix.lower() in IMAGE_EXTENSIONS and p.is_file() and not p.name.startswith(".")


def confine(path: Path, root: Path, opts: ReadOptions, what: str) -> Path:
    """``path`` if it resolves (symlinks followed) inside ``root``, else a SceneError (unless
    the options allow paths outside the scene)."""
    try:
        res = path.resolve()
        top = root.resolve()
    except (OSError, RuntimeError) as e:
        raise SceneError(f"{what}: cannot resolve {path} ({e})") from None
    if not opts.allow_outside and res != top and top not in res.parents:
        raise SceneError(f"{what}: {path} lies outside the scene folder {root} (refused; "
                         "pass --allow-outside-paths to read it)")
    return path


def check_count(n: int, what: str, opts: ReadOptions) -> None:
    if n > opts.limits.max_views:
        raise SceneError(f"{what}: {n} views exceed the limit of {opts.limits.max_views}")


def number(v, what: str, *, positive: bool = False) -> float:
    """A finite float from a JSON/config value, or a SceneError naming ``what``."""
    try:
        x = float(v)
    except (TypeError, ValueError):
        raise SceneError(f"{what} must be a number, got {v!r}") from None
    if not math.isfinite(x) or (positive and x <= 0):
        raise SceneError(f"{what} must be a finite{' positive' if positive else ''} number, got {v!r}")
    return x


def load_views(paths: list[Path], what: str, opts: ReadOptions = ReadOptions(), lazy: bool = False):
    """Read image files that must all share size, channels and depth.

    Every header is read first (sizes, channels, depth checked against each other and the
    limits) before any pixel is decoded.

    Args:
        paths: image files in view order.
        what: the scene's name for messages.
        lazy: return the files unread (:class:`ImageFiles`, decoded per view when indexed).

    Returns:
        (N, H, W, C) array in the files' common dtype (decoded into one array on a few threads,
        never a second copy), or :class:`ImageFiles` when ``lazy``.

    Raises:
        SceneError: a missing or unreadable file, or files that disagree in size/channels/depth
            or exceed the limits.
    """
    if not paths:
        raise SceneError(f"{what}: no views found")
    check_count(len(paths), what, opts)
    for p in paths:
        if not os.path.isfile(p):
            raise SceneError(f"{what}: missing view {p}")
    heads = [image_size(p) for p in paths]
    h, w, c, fmt = heads[0]
    if h * w > opts.limits.max_view_pixels:
        raise SceneError(f"{what}: views of {h}x{w} pixels exceed the limit of {opts.limits.max_view_pixels}")
    if len(paths) * h * w > opts.limits.max_scene_pixels:
        raise SceneError(f"{what}: {len(paths)} views of {h}x{w} pixels exceed the limit of "
                         f"{opts.limits.max_scene_pixels} pixels per scene")
    for p, hd in zip(paths, heads):
        if hd != heads[0]:
            raise SceneError(
                f"{what}: view {p.name} is {hd[0]}x{hd[1]}x{hd[2]} {hd[3]}, but {paths[0].name} is "
                f"{h}x{w}x{c} {fmt}; all views must share size, channels and bit depth")
    files = ImageFiles(paths, (h, w, c, fmt), what, opts)
    return files if lazy else np.asarray(files)


def _sample_dtype(fmt: str) -> np.dtype:
    """The dtype :func:`formats.imageio.read_image` gives a file whose header names ``fmt``."""
    return np.dtype(np.uint8 if fmt in ("uint8", "int8") else np.uint16 if fmt in ("uint16", "int16")
                    else np.float32)


@dataclass(frozen=True)
class ImageFile:
    """One view's image file as the scene was opened: its size and modification time, and the
    shape and depth it must decode to. Small and picklable, so that a worker process on the same
    machine reads its view itself (the ``tx`` encoder's process pool)."""

    path: Path
    stamp: tuple[int, int]             # (bytes, st_mtime_ns)
    shape: tuple[int, int, int]        # (H, W, C)
    dtype: np.dtype
    what: str                          # the scene, for messages
    max_pixels: int
    first: str                         # the scene's first file, for messages

    @staticmethod
    def stamp_of(p: Path, what: str) -> tuple[int, int]:
        try:
            st = os.stat(p)
        except OSError as e:
            raise SceneError(f"{what}: cannot read view {p} ({e.strerror or e})") from None
        return st.st_size, st.st_mtime_ns

    def read(self) -> np.ndarray:
        """(H, W, C) pixels, decoded from the file now. SceneError if the file changed since the
        scene was opened or decodes to another shape or depth. On a process's main thread what
        libpng prints about a broken file is held back (the error says it)."""
        if threading.current_thread() is not threading.main_thread():
            return self._read()
        with native_stderr():
            return self._read()

    def _read(self) -> np.ndarray:
        p = self.path
        if self.stamp_of(p, self.what) != self.stamp:
            raise SceneError(f"{self.what}: view {p.name} changed on disk after the scene was opened")
        im = read_image(p, self.max_pixels)
        if im.shape != self.shape or im.dtype != self.dtype:
            raise SceneError(f"{self.what}: view {p.name} decodes to {im.shape} {im.dtype}, but its header and "
                             f"{self.first} say {self.shape} {self.dtype}")
        return im


class ImageFiles:
    """(N, H, W, C) views that stay in their image files, each decoded when indexed.

    What :func:`load_views` returns with ``lazy=True``: a scene read this way costs no memory for
    its pixels until a view is asked for (``files[i]``, decoded from its file each time: the
    ``tx`` encoder reads each view about twice and keeps the few its rate search re-reads;
    its process pool's workers read their views themselves, ``files.file(i)``).
    ``np.asarray(files)`` decodes them all into one array, on a few threads. Every read checks
    that the file still has the size and modification time it had when the scene was opened and
    that it decodes to the shape and depth of the others; a view changed or replaced under an
    encode is a SceneError, never pixels of another scene mixed into the file.

    Attributes:
        shape: (N, H, W, C); dtype: uint8, uint16 or float32; paths: the files in view order.
        decodes: how many files were decoded so far (in this process).
    """

    ndim = 4

    def __init__(self, paths: list[Path], head: tuple[int, int, int, str], what: str, opts: ReadOptions):
        h, w, c, fmt = head
        self.paths, self.what, self.opts = list(paths), what, opts
        self.shape = (len(self.paths), h, w, c)
        self.dtype = _sample_dtype(fmt)
        self.nbytes = int(np.prod(self.shape)) * self.dtype.itemsize
        self.decodes = 0
        first = self.paths[0].name
        self._files = [ImageFile(p, ImageFile.stamp_of(p, what), (h, w, c), self.dtype, what,
                                 opts.limits.max_view_pixels, first) for p in self.paths]

    def file(self, i: int) -> ImageFile:
        """View i's file (read it with ``.read()``, here or in another process)."""
        return self._files[i]

    def __getitem__(self, i):
        if isinstance(i, (int, np.integer)) and not isinstance(i, bool):
            return self.read(range(self.shape[0])[i])
        return np.asarray(self)[i]

    def read(self, i: int) -> np.ndarray:
        """(H, W, C) pixels of view i, decoded from its file now."""
        self.decodes += 1
        return self._files[i].read()

    def __len__(self) -> int:
        return self.shape[0]

    def __array__(self, dtype=None, copy=None):
        out = np.empty(self.shape, self.dtype)
        n = self.shape[0]

        def one(i):
            out[i] = self.read(i)
            return i

        with native_stderr(), ThreadPoolExecutor(min(4, n)) as ex:
            for k, _ in enumerate(ex.map(one, range(n)), 1):
                if self.opts.progress is not None:
                    self.opts.progress("read views", k, n)
        return out if dtype is None else out.astype(dtype)

    def __repr__(self) -> str:
        return f"ImageFiles({self.shape[0]} views of {self.shape[1:]} {self.dtype} in {self.what})"


def as_grid(views, rows: int, cols: int):
    """(rows, cols, H, W, C) views from :func:`load_views`' (N, H, W, C): the array reshaped, or
    :class:`ImageFiles` behind a :class:`formats.viewstack.ViewStack` (still unread)."""
    if isinstance(views, np.ndarray):
        return views.reshape(rows, cols, *views.shape[1:])
    from ..viewstack import ViewStack

    return ViewStack(views, (rows, cols))
