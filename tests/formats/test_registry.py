"""The codec registry (formats.registry) and the RLFC profiles' (rlfc.profiles): built-in ids
resolve without scanning entry points, the built-in tables are the entry points pyproject.toml
declares, unknown ids are typed errors, codecs registered at run time come first, and opening a
local file does not import the URL reader."""
import subprocess
import sys
import tomllib

import pytest

import formats.registry as reg
import rlfc.profiles as profiles
from formats.codec_api import Codec
from formats.errors import UnsupportedError
from tests.conftest import ROOT


def test_builtin_codecs_are_the_declared_entry_points():
    eps = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["entry-points"]["lfcodec.codecs"]
    assert reg.BUILTIN == eps


def test_builtin_ids_resolve_without_scanning_entry_points(monkeypatch):
    def scan():
        raise AssertionError("entry points scanned")

    monkeypatch.setattr(reg, "_entry_points", scan)
    monkeypatch.setattr(profiles, "_entry_points", scan)
    monkeypatch.setattr(reg, "_instances", {})
    assert reg.get_codec("rlfc").codec_id == "rlfc"
    assert reg.get_codec("lfn").codec_id == "lfn"
    for pid in ("tx", "dcp", "bise"):
        assert profiles.get_profile(pid) is not None


def test_unknown_ids_are_typed_errors_that_list_the_known():
    with pytest.raises(UnsupportedError, match="'nope'.*known: lfn, rlfc"):
        reg.get_codec("nope")
    with pytest.raises(UnsupportedError, match="'nope'.*known: bise, dcp, tx"):
        profiles.get_profile("nope")
    assert {"lfn", "rlfc"} <= set(reg.available_codecs())


def test_codecs_registered_at_run_time_come_first(monkeypatch):
    monkeypatch.setattr(reg, "_registered", {})
    monkeypatch.setattr(reg, "_instances", {})

    class Mine(type(reg.get_codec("rlfc"))):
        pass

    reg.register_codec(Mine, "rlfc")
    assert type(reg.get_codec("rlfc")) is Mine

    class NotACodec:
        codec_id = "odd"

    reg.register_codec(NotACodec)
    with pytest.raises(UnsupportedError, match="does not implement"):
        reg.get_codec("odd")
    assert issubclass(Mine, Codec)


def _small_file(tmp_path):
    """A 2×2 grid of 16² views coded with ``tx``, written to tmp_path/a.lfc."""
    import numpy as np

    from rlfc import encode
    from tests.rlfc.helpers import make_lf, open_encoded

    lf = make_lf(np.random.default_rng(0).integers(0, 255, (2, 2, 16, 16, 3), np.uint8))
    path = tmp_path / "a.lfc"
    path.write_bytes(open_encoded(lf, encode(lf, profile="tx", step=2.0))[1])
    return path


def _run_without_scan(lines: str):
    """Run ``lines`` in a fresh interpreter, then check it imported neither the URL reader nor
    importlib.metadata."""
    code = ("import sys\n" + lines +
            "bad = [m for m in ('formats.remote', 'importlib.metadata') if m in sys.modules]\n"
            "assert not bad, bad\n")
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, (lines, r.stderr)


def test_opening_a_local_file_needs_no_url_reader(tmp_path):
    """formats.remote (and urllib with it, ~20 ms) loads only for URLs; importlib.metadata only
    where an id is not built in."""
    path = _small_file(tmp_path)
    _run_without_scan("from formats import open_lfc, open_decoder\n"
                      f"open_decoder(open_lfc({str(path)!r})).decode_view(1, 1)\n")


def test_a_set_is_named_by_its_codecs_suffix(monkeypatch):
    assert reg.set_codec("scene/tiles.JSON").codec_id == "lfn"

    def scan():
        raise AssertionError("entry points scanned")

    monkeypatch.setattr(reg, "_entry_points", scan)
    assert reg.set_codec("a/b.lfc") is None and reg.set_codec("http://h/x.LFC") is None


def test_commands_on_a_file_load_no_plug_in_scan(tmp_path):
    """``lfcodec info`` / ``decode`` / ``render`` of an .lfc file build only their own command's
    options (encode's codec groups would load every plug-in) and import neither
    importlib.metadata nor the URL reader."""
    path = _small_file(tmp_path)
    for args in (["info", str(path)], ["decode", str(path), str(tmp_path / "b.png"), "--block", "1,1,0,0"],
                 ["render", str(path), str(tmp_path / "c.png"), "--at", "0.5,0.5", "--quiet"]):
        _run_without_scan(f"from formats.cli import main\nassert main({args!r}) == 0\n")
