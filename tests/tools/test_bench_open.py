"""tools.bench_open: fresh-process timings of opening a file, its first blocks and its first
rendered frame, against an older checkout (here: the same code), on a golden file."""
import json

from tests.conftest import ROOT
from tools import bench_open


def test_bench_open_measures_every_key_for_both_versions(tmp_path, capsys):
    f = ROOT / "tests" / "data" / "golden" / "rlfc_txsplit_lossy_rgb8.lfc"
    out = tmp_path / "open.jsonl"
    assert bench_open.main([str(f), "--rounds", "1", "--against", str(ROOT), "--out", str(out)]) == 0
    rows = [json.loads(x) for x in out.read_text().splitlines()]
    assert [r["ver"] for r in rows] == ["new", "old"]
    for r in rows:
        assert set(r["r"]) == set(bench_open.KEYS)
        assert r["r"]["open_first_frame_ms"] >= r["r"]["first_frame_ms"] > 0
    assert "open_first_frame_ms" in capsys.readouterr().out
