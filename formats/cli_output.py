"""What the ``lfcodec`` commands print: progress bars on stderr (:class:`Progress`) and strict
JSON (:func:`dump_json`)."""
from __future__ import annotations

import json
import sys

import numpy as np


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


class Progress:
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


def dump_json(obj) -> str:
    """Strict JSON (no NaN/Infinity)."""
    return json.dumps(_finite(obj), allow_nan=False)
