"""tools.bench_web_workers: the viewer's frames on Web Workers against the page's thread, in Chromium."""
from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

from tools.bench_web_workers import main

GOLDEN = Path(__file__).resolve().parents[1] / "data" / "golden"
CHROMIUM = os.environ.get("LFC_CHROMIUM") or shutil.which("chromium") or shutil.which("chromium-browser")


@pytest.mark.skipif(CHROMIUM is None, reason="Chromium is not installed")
def test_the_table_of_a_golden_file(capsys):
    pytest.importorskip("playwright")
    assert main([str(GOLDEN / "rlfc_tx6_alpha_rgba8.lfc"), "--rounds", "1"]) == 0
    row = capsys.readouterr().out.strip().splitlines()[-1].split("|")
    assert row[1].strip() == "rlfc_tx6_alpha_rgba8" and row[4].strip() == "True"
    assert float(row[2]) >= 0 and float(row[3].split("(")[0]) >= 0


@pytest.mark.skipif(CHROMIUM is None, reason="Chromium is not installed")
def test_settings_against_a_baseline(capsys):
    """--settings: any URL query settings against the first (the blend's loops against WebAssembly)."""
    pytest.importorskip("playwright")
    assert main([str(GOLDEN / "rlfc_tx5_warped_rgb8.lfc"), "--rounds", "1", "--settings",
                 "workers=0&wasm=0,workers=0"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert "&workers=0&wasm=0 ms" in lines[0] and "&workers=0 ms (ratio)" in lines[0]
    row = lines[-1].split("|")
    assert row[1].strip() == "rlfc_tx5_warped_rgb8" and row[4].strip() == "True"
