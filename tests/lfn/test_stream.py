"""lfn_stream.stream.LfnStream: an LFN file read and checked without torch — what ``lfcodec
info`` uses. It refuses what LfnRenderer refuses (the same typed errors), describes a file as
the renderer does, and a CLI ``info`` of a network imports no torch."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from formats.container import build_container
from formats.errors import FormatError
from formats.lfcfile import encode_meta, open_lfc
from lfn_stream import LfnRenderer, LfnStream
from lfn_stream.pack import step_offsets
from tests.formats.test_web_lfn import lfn_file, r_cfg

ROOT = Path(__file__).resolve().parents[2]


def rewrite(src: Path, out: Path, change) -> Path:
    """``src`` with its sections passed through ``change(name, bytes) -> bytes``."""
    f = open_lfc(src)
    meta = f.meta
    secs = [(n, change(n, bytes(f.container.read(n)))) for n in f.container.sections if n != "meta"]
    m = encode_meta(meta["codec"], meta["codec_version"], meta["config"], meta["scene"],
                    {"more": meta["more"]} if "more" in meta else None)
    out.write_bytes(b"".join(bytes(x) for x in build_container(m, secs)))
    return out


def test_the_stream_describes_a_file_as_the_renderer_does(tmp_path):
    path = lfn_file(tmp_path, 4, display_scales=[[0.25, [6, 9, 14, 20]]])
    assert LfnStream(open_lfc(path)).info() == LfnRenderer(open_lfc(path), device="cpu").info()
    part = LfnStream(open_lfc(path), max_neurons=9)
    assert part.neurons == 9 and part.levels == 3 and part.display_neurons_at(0.25) == 9


@pytest.mark.parametrize("case", ["step-nan", "occ-nan", "base-inf", "base-short"])
def test_the_stream_refuses_what_the_renderer_refuses(tmp_path, case):
    src = lfn_file(tmp_path, 4, weights="fp16")
    at = int(step_offsets(r_cfg(open_lfc(src)), "fp16")[3])        # step 3 inside lfn.steps

    def change(name, data):
        if case == "step-nan" and name == "lfn.steps":
            return data[:at] + b"\x00\x7e" + data[at + 2:]
        if case == "occ-nan" and name == "lfn.occ":
            return data[:4] + b"\x00\x7e" + data[6:]
        if case == "base-inf" and name == "lfn.base":
            return data[:8] + b"\x00\x7c" + data[10:]
        if case == "base-short" and name == "lfn.base":
            return data[:-2]
        return data

    bad = rewrite(src, tmp_path / f"{case}.lfc", change)
    with pytest.raises(FormatError) as a:
        LfnRenderer(open_lfc(bad), device="cpu")
    with pytest.raises(FormatError) as b:
        LfnStream(open_lfc(bad))
    assert str(a.value) == str(b.value)
    from formats.cli import main

    assert main(["info", str(bad)]) == 2


def test_info_of_a_network_imports_no_torch(tmp_path):
    """``lfcodec info net.lfc`` checks and describes the network without importing torch (1.6 s
    of the 2.2 s it took on the 2-core box)."""
    path = lfn_file(tmp_path, 3, display=[6, 9, 20])
    code = ("import sys, json, io, contextlib\n"
            "from formats.cli import main\n"
            "buf = io.StringIO()\n"
            "with contextlib.redirect_stdout(buf):\n"
            f"    assert main(['info', {str(path)!r}, '--json']) == 0\n"
            "assert 'torch' not in sys.modules, 'torch imported'\n"
            "print(buf.getvalue())\n")
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    got = json.loads(r.stdout)["decoder"]
    want = LfnRenderer(open_lfc(path), device="cpu").info()
    assert got == json.loads(json.dumps(want)) and np.isfinite(got["first_renderable_bytes"])
