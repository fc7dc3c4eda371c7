"""tools.web_render_parity: the viewer's frames against the Python renderer's, as a table."""
from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from tools.web_render_parity import cameras, compare, main

GOLDEN = Path(__file__).resolve().parents[1] / "data" / "golden"


def test_compare_reports_the_worst_frame():
    a = np.zeros((4, 5, 3), np.uint8)
    b = a.copy()
    b[0, 0, 0] = 7
    worst, big, share = compare([a, a], [a, b])
    assert big == 7 and share == pytest.approx(1 / 120)
    assert worst == pytest.approx(10 * np.log10(255 ** 2 / (49 / 60)))
    assert compare([a], [a])[0] == np.inf
    assert len(cameras(3, 4)) == 44 and {c[4] for c in cameras(3, 4)} == {True, False}


@pytest.mark.skipif(shutil.which("node") is None, reason="Node.js is not installed")
def test_the_table_of_a_golden_file(capsys):
    assert main([str(GOLDEN / "rlfc_tx6_alpha_rgba8.lfc")]) == 0
    row = capsys.readouterr().out.strip().splitlines()[-1].split("|")
    assert row[1].strip() == "rlfc_tx6_alpha_rgba8"
    worst, big, share, _ = (x.strip() for x in row[3].split("/"))
    assert float(worst) > 60 and int(big) <= 3 and float(share.rstrip("%")) < 0.1
