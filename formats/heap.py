"""The C heap of a process that codes light fields (glibc's malloc; elsewhere these do nothing).

Coding a light field allocates and frees many arrays of a few MiB on a few threads. glibc gives
each thread that contends for the heap an arena of its own and keeps what is freed in each for
reuse, so a process's resident memory settles well above what it holds (hci_antinous 9×9 at
40 dB: 291 MiB peak against 249–258 MiB with one arena; BENCHMARKS.md). ``lfcodec`` asks for one
arena when it starts (:func:`limit_arenas`) and trims the heap between an encode and the decode
that measures its file (:func:`trim`). A program calling the library can do the same, or set
``MALLOC_ARENA_MAX=1`` in the environment.
"""
from __future__ import annotations

import ctypes
import os
import sys

M_ARENA_MAX = -8          # mallopt parameters (glibc malloc.h)
M_TRIM_THRESHOLD = -1
M_MMAP_THRESHOLD = -3
#: :func:`keep_freed`'s defaults: blocks below this come from the heap (glibc's own ceiling for
#: its moving threshold), and the heap keeps this much freed memory at its top
KEEP_MMAP_BYTES = 32 << 20
KEEP_TRIM_BYTES = 64 << 20


def _libc():
    if not sys.platform.startswith("linux"):
        return None
    try:
        return ctypes.CDLL(None)             # (the process's own symbols, libc's among them: no
        #                                      ctypes.util, whose import and search cost ~10-25 ms)
    except OSError:
        return None


def limit_arenas(n: int = 1) -> bool:
    """Ask malloc for at most ``n`` arenas (threads then share them; it takes effect for the
    arenas made after the call, so call it before starting threads). Leaves a
    ``MALLOC_ARENA_MAX`` set in the environment alone. Returns whether the limit was set."""
    if "MALLOC_ARENA_MAX" in os.environ:
        return False
    libc = _libc()
    try:
        return bool(libc is not None and libc.mallopt(M_ARENA_MAX, int(n)) == 1)
    except AttributeError:                  # not glibc (musl has no mallopt arenas)
        return False


def keep_freed(mmap_bytes: int = KEEP_MMAP_BYTES, trim_bytes: int = KEEP_TRIM_BYTES) -> bool:
    """Ask malloc to serve blocks below ``mmap_bytes`` from the heap and to keep up to
    ``trim_bytes`` of freed memory at the heap's top, for a process that decodes or renders
    frame after frame. glibc's defaults give large blocks pages of their own (or give the heap's
    top back) and map them again on the next frame, a page fault per 4 KiB: on the 2-core box
    ``lfcodec render FILE DIR --path orbit:60`` took 400 000 page faults and 2.7-2.9 s, and 53 000
    and 2.0-2.1 s with this; warm frames ran 1.3-1.8x as fast; peaks 0-7% higher (BENCHMARKS.md).
    ``lfcodec render`` and the library's renderer (:class:`rlfc.render.Renderer`, unless made
    with ``keep_freed=False``) ask for it (not ``decode``: one pass, no faster, a peak up to 23%
    higher; nor ``encode``, whose peak-memory line it would cross). Leaves the environment's ``MALLOC_MMAP_THRESHOLD_`` / ``MALLOC_TRIM_THRESHOLD_`` alone.
    Returns whether both were set."""
    if "MALLOC_MMAP_THRESHOLD_" in os.environ or "MALLOC_TRIM_THRESHOLD_" in os.environ:
        return False
    libc = _libc()
    try:
        return bool(libc is not None and libc.mallopt(M_MMAP_THRESHOLD, int(mmap_bytes)) == 1
                    and libc.mallopt(M_TRIM_THRESHOLD, int(trim_bytes)) == 1)
    except AttributeError:                  # not glibc
        return False


def trim() -> None:
    """Give the memory freed so far back to the system (``malloc_trim``): without it, what runs
    next allocates beside the freed arenas (hci_antinous at 40 dB with ``--json``: the decode that
    measures the file peaked at 378 MB, above the encode's 342; with it, 334)."""
    libc = _libc()
    try:
        if libc is not None:
            libc.malloc_trim(0)
    except AttributeError:
        pass


__all__ = ["keep_freed", "limit_arenas", "trim"]
