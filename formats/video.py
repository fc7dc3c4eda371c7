"""Writing rendered sequences: a folder of PNG frames, or an MP4 through ffmpeg when present.

PNG frames keep the light field's own pixels (grey, RGBA, 16-bit), named ``frame_00000.png``…,
each written atomically. A folder that holds frames already is refused (the two sequences would
mix) unless ``overwrite``; then frames of the earlier sequence past the new one's end go too.
An MP4 needs 8-bit RGB of even size: grey is repeated over R, G, B, 16-bit samples keep their
high byte, RGBA is composited on black, and an odd height or width
gets one more row or column (a copy of the last). The MP4 is written to a temporary file in
the output's folder by ffmpeg (H.264 when ffmpeg has libx264, else MPEG-4 part 2) and renamed
when complete, so an interrupted run never leaves a broken OUT.mp4.
"""
from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np

from .errors import ParameterError, UnsupportedError


def video_frame(img: np.ndarray) -> np.ndarray:
    """(H, W, C) frame of any supported layout → (H', W', 3) uint8 RGB of even size."""
    x = img
    if x.dtype == np.uint16:
        x = (x >> 8).astype(np.uint8)
    if x.shape[-1] in (2, 4):                              # alpha: composite on black
        a = x[..., -1:].astype(np.uint16)
        x = ((x[..., :-1].astype(np.uint16) * a + 127) // 255).astype(np.uint8)
    if x.shape[-1] == 1:
        x = np.repeat(x, 3, axis=-1)
    h, w = x.shape[:2]
    if h % 2 or w % 2:
        x = np.pad(x, ((0, h % 2), (0, w % 2), (0, 0)), mode="edge")
    return np.ascontiguousarray(x)


def frame_files(folder: Path) -> list:
    """The PNG frames of a sequence in ``folder`` (``frame_NNNNN.png``), in frame order."""
    got = [p for p in folder.glob("frame_*.png") if re.fullmatch(r"frame_\d{5,}\.png", p.name)]
    return sorted(got, key=lambda p: int(p.stem[6:]))


def ffmpeg_encoder() -> tuple[str, str] | None:
    """(ffmpeg path, video encoder name) or None when ffmpeg is not on PATH."""
    exe = shutil.which("ffmpeg")
    if exe is None:
        return None
    try:
        r = subprocess.run([exe, "-hide_banner", "-encoders"], capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.SubprocessError):
        return None
    return exe, ("libx264" if " libx264 " in r.stdout else "mpeg4")


class SequenceWriter:
    """Frames → a PNG folder (``out`` without a video suffix) or an MP4 (``out`` ending .mp4).

    Use as a context manager; :meth:`write` takes (H, W, C) frames of one size.

    Raises:
        ParameterError: a bad frame rate or output; UnsupportedError: an MP4 without ffmpeg.
    """

    def __init__(self, out: str | os.PathLike, fps: float = 30.0, overwrite: bool = False):
        self.out = Path(out)
        self.overwrite = overwrite
        if not (isinstance(fps, (int, float)) and np.isfinite(fps) and 0 < fps <= 1000):
            raise ParameterError(f"--fps must be within (0, 1000], got {fps}")
        self.fps = float(fps)
        self.frames = 0
        self.mp4 = self.out.suffix.lower() == ".mp4"
        self._proc = None
        self._pool, self._pending = None, []
        if self.out.suffix.lower() in (".png", ".jpg", ".gif", ".avi", ".mov", ".mkv", ".webm"):
            raise ParameterError(f"{self.out}: a camera path writes a folder of PNG frames or an .mp4 file")
        from .imageio import check_parent_folder

        check_parent_folder(self.out)
        if self.mp4 and self.out.is_dir():
            raise ParameterError(f"{self.out}: is a folder; name the .mp4 file, or give a folder without .mp4 for "
                                 f"PNG frames")
        if self.mp4:
            enc = ffmpeg_encoder()
            if enc is None:
                raise UnsupportedError("writing MP4 needs ffmpeg on PATH (apt-get install ffmpeg); or give a "
                                       "folder for PNG frames")
            self.exe, self.codec = enc
            self.tmp = self.out.with_name(f".{self.out.name}.tmp{os.getpid()}.mp4")
        elif self.out.exists() and not self.out.is_dir():
            raise ParameterError(f"{self.out}: exists and is not a folder")
        elif self.out.is_dir():
            old = frame_files(self.out)
            if old and not overwrite:             # another run's frames: mixed in, a sequence would lie
                raise ParameterError(f"{self.out}: holds {len(old)} frames of an earlier sequence ({old[0].name} …); "
                                     f"give --overwrite to replace them, or another folder")

    def __enter__(self):
        return self

    #: PNG frames written on a background thread while the next frame renders, at most this
    #: many waiting (a 60-frame orbit spent 1.9 of its 5.8 s writing them in line)
    PENDING = 2

    def write(self, img: np.ndarray) -> None:
        if not self.mp4:
            from concurrent.futures import ThreadPoolExecutor

            from .imageio import write_image

            self.out.mkdir(exist_ok=True)
            if self._pool is None:
                self._pool = ThreadPoolExecutor(1)
            while len(self._pending) >= self.PENDING:
                self._pending.pop(0).result()            # (a failed write raises here)
            self._pending.append(self._pool.submit(write_image, self.out / f"frame_{self.frames:05d}.png",
                                                   np.array(img)))
            self.frames += 1
            return
        f = video_frame(img)
        if self._proc is None:
            h, w = f.shape[:2]
            self.size = (h, w)
            cmd = [self.exe, "-hide_banner", "-loglevel", "error", "-y", "-f", "rawvideo", "-pix_fmt", "rgb24",
                   "-s", f"{w}x{h}", "-r", f"{self.fps:g}", "-i", "-", "-c:v", self.codec, "-pix_fmt", "yuv420p"]
            cmd += ["-crf", "18"] if self.codec == "libx264" else ["-q:v", "3"]
            self._proc = subprocess.Popen(cmd + ["-f", "mp4", str(self.tmp)], stdin=subprocess.PIPE,
                                          stderr=subprocess.PIPE)
        if f.shape[:2] != self.size:
            raise ParameterError("all frames of a sequence must have one size")
        try:
            self._proc.stdin.write(f.tobytes())
        except BrokenPipeError:
            raise UnsupportedError(f"ffmpeg stopped: {self._stderr()}") from None
        self.frames += 1

    def _stderr(self) -> str:
        err = self._proc.stderr.read().decode("utf-8", "replace").strip().splitlines() if self._proc.stderr else []
        return err[-1][:200] if err else f"exit code {self._proc.returncode}"

    def _drain(self, ok: bool) -> None:
        """Every PNG frame written (ok) or the pending ones dropped; the writer thread ended."""
        pending, self._pending = self._pending, []
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=not ok)
            self._pool = None
        if ok:
            for w in pending:
                w.result()

    def close(self, ok: bool = True) -> None:
        if not self.mp4:
            self._drain(ok)
            if ok and self.overwrite:             # an earlier, longer sequence's frames past this one's end
                for f in frame_files(self.out):
                    if int(f.stem[6:]) >= self.frames:
                        f.unlink(missing_ok=True)
            return
        if self._proc is None:
            return
        proc, self._proc = self._proc, None
        try:
            proc.stdin.close()
        except BrokenPipeError:
            pass
        rc = proc.wait()
        if not ok:
            self.tmp.unlink(missing_ok=True)
            return
        if rc != 0:
            self._proc = proc
            msg = self._stderr()
            self._proc = None
            self.tmp.unlink(missing_ok=True)
            raise UnsupportedError(f"ffmpeg could not write {self.out}: {msg}")
        os.replace(self.tmp, self.out)

    def __exit__(self, et, ev, tb):
        self.close(ok=et is None)
        return False
