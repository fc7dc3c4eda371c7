"""Every option of every subcommand, given bad values: exit code 2 with one line, or a run that
succeeds (exit 0) — never a traceback (issue 15). Runs in-process on a tiny grid."""
import argparse

import pytest

from formats.cli import build_parser, main
from formats.scenes import write_views
from tests.rlfc.helpers import smooth_lf

BAD = ["-1", "0", "nan", "inf", "abc", "1e309", "99999999999", ""]
SKIP = {"help", "version"}


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    root = tmp_path_factory.mktemp("opts")
    lf = smooth_lf(rows=2, cols=2, h=16, w=16)
    write_views(root / "plain", lf.views)
    assert main(["encode", str(root / "plain"), str(root / "t.lfc"), "--grid", "2x2", "--quant", "8", "--quiet"]) == 0
    assert main(["decode", str(root / "t.lfc"), str(root / "scene"), "--quiet"]) == 0      # writes scene.json
    return root


def _options(cmd):
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction)).choices[cmd]
    for act in sub._actions:
        if act.option_strings and act.dest not in SKIP and act.nargs != 0:
            yield act.option_strings[-1]


def _base(cmd, root, out):
    return {"encode": ["encode", str(root / "scene"), str(out)],
            "decode": ["decode", str(root / "t.lfc"), str(out)],
            "info": ["info", str(root / "t.lfc")],
            "serve": ["serve", str(root)],
            "view": ["view", str(root / "t.lfc")],
            "render": ["render", str(root / "t.lfc"), str(out) + ".png", "--at", "0.5,0.5"],
            "train": ["train", str(root / "scene"), str(out), "--steps", "1", "--max-neurons", "32"]}[cmd]


@pytest.mark.parametrize("cmd", ["encode", "decode", "render", "train", "serve", "view"])
def test_every_option_with_bad_values_exits_0_or_2(cmd, tiny, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)        # a bad value may be a valid file name (--checkpoint nan): keep it here
    from formats.serve import FileServer

    monkeypatch.setattr(FileServer, "serve_forever", lambda self: None)   # serve/view: bind, print, return
    seen = 0
    for opt in _options(cmd):
        if cmd == "train" and opt == "--steps":
            continue                                          # (kept at 1: a one-step training)
        if cmd == "encode" and opt in ("--steps", "--batch", "--resolution", "--lr", "--holdout", "--depth",
                                       "--min-neurons", "--max-neurons", "--occupancy-neurons", "--device",
                                       "--weights", "--checkpoint"):
            continue                                          # lfn options: refused for rlfc (below)
        for bad in BAD:
            out = tmp_path / f"o{seen}"
            argv = _base(cmd, tiny, out) + [opt, bad] + (["--quiet"] if cmd not in ("info", "serve", "view") else [])
            try:
                rc = main(argv)
            except SystemExit as e:                            # argparse: one error line, exit 2
                rc = e.code
            err = capsys.readouterr().err
            assert rc in (0, 2), (argv, rc, err)
            assert "Traceback" not in err and "usage:" not in err, (argv, err)
            if rc == 2:                                        # one line says what was wrong
                assert err.strip() and "error" in err.strip().splitlines()[-1], argv
            seen += 1
    assert seen > 0


def test_lfn_options_do_not_apply_to_rlfc(tiny, tmp_path, capsys):
    for opt in ("--steps", "--max-neurons", "--device"):
        assert main(["encode", str(tiny / "scene"), str(tmp_path / "x.lfc"), opt, "5", "--quiet"]) == 2
        assert "do not apply" in capsys.readouterr().err


def test_lfn_render_options_on_an_rlfc_file_say_which(tiny, tmp_path, capsys):
    """render's network-only options on an RLFC file: one line naming them, in plain grammar."""
    enc = tmp_path / "r.lfc"
    assert main(["encode", str(tiny / "scene"), str(enc), "--quiet"]) == 0
    capsys.readouterr()
    assert main(["render", str(enc), str(tmp_path / "a.png"), "--level", "1", "--quiet"]) == 2
    assert "--level is an option for light field network files (this is rlfc)" in capsys.readouterr().err
    assert main(["render", str(enc), str(tmp_path / "b.png"), "--level", "1", "--scale", "2", "--quiet"]) == 2
    assert "--level, --scale are options for light field network files" in capsys.readouterr().err
