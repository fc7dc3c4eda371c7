"""The benchmark runner's --quick smoke mode on the bundled sample: every output is written and
missing optional peers are reported as skipped, not as errors."""
import json

from tests.conftest import ROOT
from tools import peers
from tools.bench import main


def test_quick_bench_writes_everything(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(peers.Hevc, "available", lambda self: "ffmpeg not on PATH")   # simulate a missing peer
    assert main([str(ROOT / "samples" / "dino_crop"), "--out", str(tmp_path), "--quick"]) == 0
    res = json.loads((tmp_path / "results.json").read_text())
    rows = res["scenes"]["dino_crop"]
    ours = [r for r in rows if r["codec"].startswith("lfcodec")]
    assert ours and ours[0]["block_us"] > 0 and ours[0]["progressive"]
    assert any(r["codec"].startswith("JPEG 2000") and "bpp" in r for r in rows)
    assert {"codec": "HEVC x265 (pseudo-sequence)", "skipped": "ffmpeg not on PATH"} in rows
    for f in ("results.csv", "summary.md"):
        assert (tmp_path / f).stat().st_size > 0
    out = capsys.readouterr().out
    assert "bpp @ 40 dB" in out and "Bit budget" in out
