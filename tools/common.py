"""Helpers every benchmark tool shares (written once here): logging, timing, the machine's
description, and building .lfc files in memory."""
from __future__ import annotations

import os
import platform
import statistics
import sys
import time

import numpy as np

from formats.lfcfile import lfc_bytes, open_lfc


def log(msg: str) -> None:
    """A progress line on stderr (results go to stdout and files)."""
    print(msg, file=sys.stderr, flush=True)


def compile_checkouts(*roots) -> None:
    """Byte-compile the packages of each checkout (``formats``, ``rlfc``, ``lfn_stream``), so that
    processes timed from their start load .pyc files in every version: with
    ``PYTHONDONTWRITEBYTECODE`` set, a checkout extracted for a side-by-side run would compile every
    module at every start (~150 ms on the 2-core box) while the working tree used its cached ones."""
    import compileall
    from pathlib import Path

    for root in roots:
        for pkg in ("formats", "rlfc", "lfn_stream"):
            if (Path(root) / pkg).is_dir():
                compileall.compile_dir(str(Path(root) / pkg), quiet=2, workers=1)


def median_time(fn, repeats: int, warmup: bool = True) -> float:
    """Median seconds of ``fn()`` over ``repeats`` calls (after one warm-up call)."""
    if warmup:
        fn()
    ts = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t)
    return statistics.median(ts)


def median_time_result(fn, repeats: int = 3):
    """(median seconds, last result) of ``fn()`` over ``repeats`` calls, no warm-up."""
    ts, out = [], None
    for _ in range(repeats):
        t = time.perf_counter()
        out = fn()
        ts.append(time.perf_counter() - t)
    return statistics.median(ts), out


def write_json(path, obj) -> None:
    """Write a benchmark's results as indented JSON to ``path`` (nothing when path is None)."""
    import json

    if path:
        with open(path, "w") as f:
            json.dump(obj, f, indent=1)


def machine() -> str:
    """CPU model, cores and library versions, for the header of every table."""
    cpu = "unknown CPU"
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{cpu}, {os.cpu_count()} cores, Python {platform.python_version()}, numpy {np.__version__}"




def open_encoded(lf, encoded, codec: str = "rlfc", version: int = 1):
    """(decoder, file bytes) of an :class:`formats.codec_api.Encoded` (or (config, sections)) in memory."""
    from formats.registry import open_decoder

    cfg, secs = (encoded.config, encoded.sections) if hasattr(encoded, "config") else encoded
    blob = lfc_bytes(codec, version, cfg, lf.geometry(), secs)
    return open_decoder(open_lfc(blob)), blob
