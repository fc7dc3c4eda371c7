"""The C heap settings lfcodec asks for (formats.heap): one malloc arena for the coding threads."""
import os
import subprocess
import sys

import pytest

from formats import heap

CHILD = r"""
import ctypes, sys, threading
import numpy as np
from formats import heap
if sys.argv[1] == "one":
    assert heap.limit_arenas(1)
def work():
    for _ in range(50):
        np.ones(100_000).sum()            # below the mmap threshold: from an arena
ts = [threading.Thread(target=work) for _ in range(4)]
[t.start() for t in ts]
[t.join() for t in ts]
heap.trim()
ctypes.CDLL("libc.so.6").malloc_stats()    # per-arena lines on stderr
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc malloc")
def test_one_arena_serves_every_thread_and_the_environment_wins(monkeypatch):
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    env.pop("MALLOC_ARENA_MAX", None)
    arenas = {}
    for mode in ("one", "default"):
        p = subprocess.run([sys.executable, "-c", CHILD, mode], env=env, capture_output=True, text=True, timeout=120)
        assert p.returncode == 0, p.stderr
        arenas[mode] = p.stderr.count("Arena ")
    assert arenas["one"] == 1 and arenas["default"] > 1
    monkeypatch.setenv("MALLOC_ARENA_MAX", "2")
    assert heap.limit_arenas(1) is False                # the user's setting stands


def test_lfcodec_asks_for_one_arena(monkeypatch, capsys):
    from formats.cli import main

    asked = []
    monkeypatch.setattr(heap, "limit_arenas", lambda n=1: asked.append(n) or True)
    assert main(["info", "/nonexistent.lfc"]) == 2
    assert asked == [1]


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc malloc")
def test_keep_freed_sets_both_thresholds_and_the_environment_wins():
    """In a child (the thresholds are the process's): set on glibc; an environment setting of
    either threshold leaves both alone."""
    code = "import sys; from formats import heap; sys.exit(0 if heap.keep_freed() else 3)"
    env = {k: v for k, v in os.environ.items() if not k.startswith("MALLOC_")}
    assert subprocess.run([sys.executable, "-c", code], env=env).returncode == 0
    env["MALLOC_TRIM_THRESHOLD_"] = str(1 << 20)
    assert subprocess.run([sys.executable, "-c", code], env=env).returncode == 3
