"""Baseline codecs a user would pick instead of lfcodec, with one interface.

Each peer's ``run(views, setting)`` returns the encoded size, the decoded views and decode
times. Per-view JPEG 2000 and JPEG XL go through imagecodecs (in memory); HEVC through
ffmpeg/libx265 as a pseudo-sequence of the views in serpentine order (4:4:4, no random
access: the unit is the whole sequence).
"""
from __future__ import annotations

import shutil
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

from tools.common import median_time_result as _median


class PerViewImageCodec:
    """Every view coded alone (random-access unit: one view); views with alpha: the colour by
    the codec, the alpha plane exact beside it (zlib)."""

    unit = "view"

    def __init__(self, name, enc, dec, settings):
        self.name, self._enc, self._dec, self.settings = name, enc, dec, settings

    def available(self) -> str | None:
        return None

    def run(self, views: np.ndarray, setting):
        from rlfc.topcodec import alpha_stream, has_alpha, read_alpha

        if has_alpha(views.shape[-1]):
            # the colour channels by this codec, the alpha plane exact beside them (zlib, as lfcodec
            # keeps it: tx version 6 codes such views the same way); every codec here is scored on
            # the colour. 4-component JPEG 2000 at a PSNR level (alpha lossy with the colour) was
            # 2.0x larger on mitsuba_objects_360 at 40 dB
            r = self.run(np.ascontiguousarray(views[..., :-1]), setting)
            streams = [alpha_stream(v[..., -1]) for v in views]
            t0 = time.perf_counter()
            alpha = np.stack([read_alpha(a, *views.shape[1:3], views.dtype, "alpha") for a in streams])
            ta = time.perf_counter() - t0
            return {"bytes": r["bytes"] + sum(map(len, streams)),
                    "decoded": np.concatenate([r["decoded"].reshape(views.shape[:-1] + (-1,)), alpha[..., None]], -1),
                    "decode_view_s": r["decode_view_s"] + ta / len(views), "decode_all_s": r["decode_all_s"] + ta}
        blobs = [self._enc(v, setting) for v in views]
        t_one, _ = _median(lambda: self._dec(blobs[len(blobs) // 2]), 5)
        t0 = time.perf_counter()
        dec = np.stack([self._dec(b).reshape(views.shape[1:]) for b in blobs])
        t_all = time.perf_counter() - t0
        return {"bytes": sum(len(b) for b in blobs), "decoded": dec, "decode_view_s": t_one, "decode_all_s": t_all}


def j2k():
    import imagecodecs

    def enc(v, s):
        a = v[..., 0] if v.shape[-1] == 1 else v
        return imagecodecs.jpeg2k_encode(a, level=0, reversible=True) if s == "lossless" else imagecodecs.jpeg2k_encode(a, level=float(s))
    return PerViewImageCodec("JPEG 2000 (per view)", enc, imagecodecs.jpeg2k_decode,
                             [32, 35, 38, 40, 42, 45, 48, 50, 53, 56, 60, "lossless"])


def jxl():
    import imagecodecs

    def enc(v, s):
        a = v[..., 0] if v.shape[-1] == 1 else v
        if s == "lossless":
            return imagecodecs.jpegxl_encode(a, lossless=True, effort=3)
        return imagecodecs.jpegxl_encode(a, distance=float(s), effort=5)
    return PerViewImageCodec("JPEG XL (per view)", enc, imagecodecs.jpegxl_decode, [6.0, 3.0, 1.5, 0.8, 0.4, 0.2, 0.1, "lossless"])


def serpentine(rows: int, cols: int) -> list[int]:
    return [r * cols + (c if r % 2 == 0 else cols - 1 - c) for r in range(rows) for c in range(cols)]


class Hevc:
    """x265 pseudo-sequence (views in serpentine order), 4:4:4, one GOP."""

    name = "HEVC x265 (pseudo-sequence)"
    unit = "whole sequence (no random access)"
    settings = [40, 34, 28, 22, 16, 10, 4]   # CRF

    def __init__(self, preset: str = "medium"):
        self.preset = preset

    def available(self) -> str | None:
        if not shutil.which("ffmpeg"):
            return "ffmpeg not on PATH"
        r = subprocess.run(["ffmpeg", "-hide_banner", "-encoders"], capture_output=True, text=True)
        return None if "libx265" in r.stdout else "ffmpeg has no libx265"

    def run(self, views: np.ndarray, crf, order=None):
        n, h, w, c = views.shape
        order = order or list(range(n))
        if c != 3 or views.dtype != np.uint8:
            raise RuntimeError("HEVC peer handles 8-bit RGB")
        with tempfile.TemporaryDirectory() as td:
            out = Path(td) / "seq.mkv"
            frames = np.ascontiguousarray(views[order])
            subprocess.run(["ffmpeg", "-v", "error", "-y", "-f", "rawvideo", "-pix_fmt", "rgb24", "-s", f"{w}x{h}",
                            "-r", "25", "-i", "-", "-c:v", "libx265", "-preset", self.preset, "-crf", str(crf),
                            "-pix_fmt", "yuv444p", "-x265-params", f"log-level=error:keyint={n}", str(out)],
                           input=frames.tobytes(), check=True)
            size = out.stat().st_size

            def decode():
                r = subprocess.run(["ffmpeg", "-v", "error", "-i", str(out), "-f", "rawvideo", "-pix_fmt", "rgb24", "-"],
                                   capture_output=True, check=True)
                return np.frombuffer(r.stdout, np.uint8).reshape(-1, h, w, 3)
            t_all, dec = _median(decode, 2)
        out_views = np.empty_like(views)
        out_views[order] = dec[:n]
        return {"bytes": size, "decoded": out_views, "decode_view_s": t_all, "decode_all_s": t_all}


class Astc:
    """ASTC (ARM astcenc), every view alone; fixed rate set by the block footprint. Its random
    access unit is one block, decoded in GPU texture hardware; CPU decode times here include
    the astcenc process start."""

    name = "ASTC astcenc (per view)"
    unit = "block (GPU texture hardware)"
    settings = ["12x12", "10x10", "8x8", "6x6", "4x4"]

    def __init__(self, quality: str = "-fast"):
        self.quality = quality

    def exe(self):
        for n in ("astcenc", "astcenc-avx2", "astcenc-sse4.1", "astcenc-sse2"):
            if shutil.which(n):
                return shutil.which(n)
        return None

    def available(self) -> str | None:
        return None if self.exe() else "astcenc not on PATH"

    def run(self, views: np.ndarray, block: str):
        from formats.imageio import read_image, write_image

        if views.dtype != np.uint8 or views.shape[-1] not in (3, 4):
            raise RuntimeError("ASTC peer handles 8-bit RGB(A)")
        exe = self.exe()
        total = 0
        dec = np.empty_like(views)
        t_one = None
        with tempfile.TemporaryDirectory() as td:
            for i, v in enumerate(views):
                src, cmp, out = Path(td) / f"{i}.png", Path(td) / f"{i}.astc", Path(td) / f"{i}d.png"
                write_image(src, v)
                subprocess.run([exe, "-cl", str(src), str(cmp), block, self.quality, "-silent"], check=True,
                               capture_output=True)
                total += cmp.stat().st_size - 16          # 16-byte .astc file header is not payload
                t = time.perf_counter()
                subprocess.run([exe, "-dl", str(cmp), str(out), "-silent"], check=True, capture_output=True)
                if i == len(views) // 2:
                    t_one = time.perf_counter() - t
                dec[i] = read_image(out)[..., :views.shape[-1]]
        # block access happens in GPU texture hardware: no CPU latency to compare with
        return {"bytes": total, "decoded": dec, "decode_view_s": t_one, "decode_all_s": t_one * len(views),
                "ra_latency_s": None}


def all_peers():
    return [j2k(), jxl(), Hevc(), Astc()]
