"""Reading and writing image files with OpenImageIO.

Pixels come back as numpy arrays of shape (H, W, C) in the file's own integer depth
(uint8 or uint16) or float32 for float formats.
"""
from __future__ import annotations

import contextlib
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

from .errors import ParameterError, SceneError

#: zlib level of the PNGs we write (OpenImageIO's default is 6): 512² RGB views of hci_antinous
#: decoded at 40 dB take 28-29 ms each at 4 against 67-79 ms at 6, in files 7.7% larger (lossless;
#: BENCHMARKS.md, decode speed)
PNG_LEVEL = 4

IMAGE_EXTENSIONS = {".png", ".jpg", ".jpeg", ".tif", ".tiff", ".exr", ".bmp", ".ppm", ".pgm", ".hdr", ".webp"}



def check_parent_folder(path) -> None:
    """A ParameterError unless the folder an output ``path`` goes in exists and is a folder (no
    folders are made on the way; a file there used to surface as a temp file's 'Not a directory')."""
    parent = Path(path).parent
    if not parent.exists():
        raise ParameterError(f"{path}: folder {parent} does not exist")
    if not parent.is_dir():
        raise ParameterError(f"{path}: {parent} is a file, not a folder")

def _oiio():
    import OpenImageIO as oiio  # imported lazily: it is slow to import

    return oiio


def _one_line(msg: str) -> str:
    """An image library's message as one short line (libpng and friends print several)."""
    lines = [x.strip() for x in (msg or "").splitlines() if x.strip()]
    return (lines[-1] if lines else "unknown format")[:200]


@contextlib.contextmanager
def native_stderr():
    """Hold what C libraries print on file descriptor 2 while image files are decoded (libpng
    prints "libpng error: ..." before OpenImageIO reports the same error, which our SceneError
    names in one line): the text is written out after the block when it ends normally and dropped
    when it raises. Python's own ``sys.stderr`` (progress bars) is not affected. Not reentrant
    across threads: enter it from one thread around the threaded reads."""
    try:
        fd = sys.stderr.fileno()
    except (AttributeError, OSError, ValueError):      # no real descriptor (pytest capture, IDEs)
        yield
        return
    with tempfile.TemporaryFile() as tmp:
        sys.stderr.flush()
        saved = os.dup(2)
        # Python's sys.stderr keeps writing to the terminal through its own duplicate
        py_fd = os.dup(saved) if fd == 2 else None
        old_stream = sys.stderr
        if py_fd is not None:
            sys.stderr = os.fdopen(py_fd, "w", buffering=1, encoding=getattr(old_stream, "encoding", None) or "utf-8",
                                   errors="backslashreplace")
        os.dup2(tmp.fileno(), 2)
        ok = False
        try:
            yield
            ok = True
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            if py_fd is not None:
                sys.stderr.flush()
                sys.stderr.close()
                sys.stderr = old_stream
            if ok:
                tmp.seek(0)
                text = tmp.read()
                if text:
                    old_stream.write(text.decode("utf-8", "replace"))
                    old_stream.flush()


def image_size(path: str | os.PathLike) -> tuple[int, int, int, str]:
    """(height, width, channels, sample type name) from an image file's header alone.

    Raises:
        SceneError: the file is missing or not a readable image.
    """
    path = str(path)
    if not os.path.isfile(path):
        raise SceneError(f"{path}: no such image file")
    if path.lower().endswith(".png"):
        try:
            with open(path, "rb") as f:
                head = _plain_png_header(f.read(1 << 16))
        except OSError:
            head = None
        if head is not None:
            return head[0], head[1], head[2], "uint8" if head[3] == 8 else "uint16"
    oiio = _oiio()
    inp = oiio.ImageInput.open(path)
    if inp is None:
        raise SceneError(f"{path}: not a readable image ({_one_line(oiio.geterror())})")
    try:
        spec = inp.spec()
        return int(spec.height), int(spec.width), int(spec.nchannels), str(spec.format)
    finally:
        inp.close()


PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
#: chunks that change what a decoder returns (transparency, significant bits, palette): a PNG
#: with any of them before its pixels goes through OpenImageIO
_PNG_SPECIAL = {b"tRNS", b"sBIT", b"PLTE"}


def _plain_png_header(data: bytes) -> tuple[int, int, int, int] | None:
    """(height, width, channels, bit depth) from the first bytes of a plain PNG file (8- or
    16-bit grey, grey + alpha, RGB or RGBA, with no palette, transparency or significant-bits
    chunk before its pixels); None for any other file or when ``data`` ends before the first
    pixel chunk."""
    import struct

    if len(data) < 45 or data[:8] != PNG_SIGNATURE or data[12:16] != b"IHDR":
        return None
    w, h = struct.unpack(">II", data[16:24])
    depth, ctype = data[24], data[25]
    if depth not in (8, 16) or ctype not in (0, 2, 4, 6) or not (h and w):
        return None
    pos = 8
    while pos + 8 <= len(data):                    # the chunks before the pixels
        n, kind = struct.unpack(">I4s", data[pos:pos + 8])
        if kind == b"IDAT":
            return h, w, {0: 1, 2: 3, 4: 2, 6: 4}[ctype], depth
        if kind in _PNG_SPECIAL:
            return None
        pos += 12 + n
    return None


def _plain_png(path: str, max_pixels: int | None) -> np.ndarray | None:
    """(H, W, C) pixels of a plain PNG (:func:`_plain_png_header`) decoded by libpng through
    imagecodecs in 0.72–0.90× the time OpenImageIO takes (best of 3 over 24 views: hci_antinous
    512² RGB 5.6 against 7.5 ms, llff_statue 960×540 8.9 against 12.3, mitsuba 256² RGBA 1.05
    against 1.19), with the same samples (tested against OpenImageIO for every kind; equal on
    all 527 PNG views of the shared scenes); None for any other file, which :func:`read_image`
    reads with OpenImageIO (and its messages). A scene of plain PNGs never loads OpenImageIO
    (31 MiB resident)."""
    try:
        with open(path, "rb") as f:
            data = f.read()
    except OSError:
        return None
    head = _plain_png_header(data)
    if head is None:
        return None
    h, w, c, depth = head
    if max_pixels is not None and w * h > max_pixels:
        raise SceneError(f"{path}: {h}x{w} pixels exceed the limit of {max_pixels} per view")
    try:
        import imagecodecs

        arr = imagecodecs.png_decode(data)
    except Exception:                              # (OpenImageIO says what is wrong)
        return None
    if arr.ndim == 2:
        arr = arr[:, :, None]
    if arr.shape != (h, w, c) or arr.dtype != (np.uint8 if depth == 8 else np.uint16):
        return None
    return np.ascontiguousarray(arr)


def read_image(path: str | os.PathLike, max_pixels: int | None = None) -> np.ndarray:
    """Read one image file.

    Args:
        path: image file (PNG, JPEG, TIFF, EXR, ...).
        max_pixels: refuse images with more pixels than this (checked from the header, before
            any pixel is read).

    Returns:
        (H, W, C) array: uint8 or uint16 for integer files, float32 for float files.

    Raises:
        SceneError: the file is missing, not a readable image, or larger than ``max_pixels``.
    """
    path = str(path)
    if not os.path.isfile(path):
        raise SceneError(f"{path}: no such image file")
    if path.lower().endswith(".png"):
        arr = _plain_png(path, max_pixels)
        if arr is not None:
            return arr
    oiio = _oiio()
    cfg = oiio.ImageSpec()
    cfg.attribute("oiio:UnassociatedAlpha", 1)   # keep straight alpha as stored (no premultiply)
    inp = oiio.ImageInput.open(path, cfg)
    if inp is None:
        raise SceneError(f"{path}: not a readable image ({_one_line(oiio.geterror())})")
    try:
        spec = inp.spec()
        if max_pixels is not None and spec.width * spec.height > max_pixels:
            raise SceneError(f"{path}: {spec.height}x{spec.width} pixels exceed the limit of {max_pixels} per view")
        if not 1 <= spec.nchannels <= 4:
            raise SceneError(f"{path}: {spec.nchannels} channels (views have 1-4)")
        fmt = spec.format.basetype
        if fmt in (oiio.UINT8, oiio.INT8):
            want = oiio.UINT8
        elif fmt in (oiio.UINT16, oiio.INT16):
            want = oiio.UINT16
        else:
            want = oiio.FLOAT
        pixels = inp.read_image(0, 0, 0, spec.nchannels, want)
        if pixels is None or not hasattr(pixels, "shape"):
            raise SceneError(f"{path}: could not decode pixels ({_one_line(inp.geterror())})")
    finally:
        inp.close()
    arr = np.asarray(pixels)
    if arr.ndim == 2:
        arr = arr[:, :, None]
    return np.ascontiguousarray(arr)


def write_image(path: str | os.PathLike, pixels: np.ndarray) -> None:
    """Write an image atomically (temp file in the same folder, then rename).

    8- and 16-bit PNGs are encoded by libpng through imagecodecs (0.7–0.8× OpenImageIO's time
    for a 512² RGB view, the same zlib level; no OpenImageIO loaded); other formats through
    OpenImageIO.

    Args:
        path: destination; the extension picks the format (e.g. .png, .tif, .exr).
        pixels: (H, W) or (H, W, C) uint8, uint16 or float32.
    """
    path = Path(path)
    arr = np.ascontiguousarray(pixels)
    if arr.ndim == 2:
        arr = arr[:, :, None]
    tmp = path.with_name(f".{path.stem}.tmp{os.getpid()}{path.suffix}")
    try:
        if path.suffix.lower() == ".png" and arr.dtype in (np.uint8, np.uint16) and 1 <= arr.shape[2] <= 4:
            import imagecodecs

            data = imagecodecs.png_encode(arr[:, :, 0] if arr.shape[2] == 1 else arr, level=PNG_LEVEL)
            with open(tmp, "wb") as f:
                f.write(data)
        else:
            _write_oiio(path, tmp, arr)
        os.replace(tmp, path)
    except OSError as e:
        raise SceneError(f"{path}: cannot write ({e.strerror})") from None
    finally:
        if os.path.lexists(tmp):                                 # (a failed write leaves no temp file)
            os.unlink(tmp)


def _write_oiio(path: Path, tmp: Path, arr: np.ndarray) -> None:
    """(H, W, C) ``arr`` written to ``tmp`` by OpenImageIO in ``path``'s format."""
    oiio = _oiio()
    typ = {np.dtype(np.uint8): oiio.UINT8, np.dtype(np.uint16): oiio.UINT16}.get(arr.dtype, oiio.FLOAT)
    if typ == oiio.FLOAT:
        arr = arr.astype(np.float32)
    spec = oiio.ImageSpec(arr.shape[1], arr.shape[0], arr.shape[2], typ)
    spec.attribute("oiio:UnassociatedAlpha", 1)      # pixels are straight alpha
    if path.suffix.lower() == ".png":
        spec.attribute("png:compressionLevel", PNG_LEVEL)
    out = oiio.ImageOutput.create(str(tmp))
    if out is None:
        raise SceneError(f"{path}: cannot write this image format ({oiio.geterror().strip()})")
    try:
        if not out.open(str(tmp), spec) or not out.write_image(arr):
            raise SceneError(f"{path}: write failed ({out.geterror().strip()})")
    finally:
        out.close()
