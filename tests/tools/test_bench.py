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


def test_bench_foveation_measures_every_mode(tmp_path, capsys):
    """The foveation benchmark on the tiny golden LFN: every mode timed and measured, the
    fovea rendered by the full network, the exact mode free of dither noise."""
    import json

    from tests.conftest import ROOT
    from tools import bench_foveation

    out = tmp_path / "fov.json"
    assert bench_foveation.main([str(ROOT / "tests/data/golden/lfn3_tiny_rgba8.lfc"), "--rounds", "1",
                                 "--sizes", "2", "4", "--inner", "0.05", "--out", str(out)]) == 0
    view = json.loads(out.read_text())["views"][0]
    assert {"exact", "dither_2", "snap_2", "dither_4", "snap_4"} <= set(view)
    for mode in ("exact", "dither_2", "dither_4", "snap_4"):
        m = view[mode]
        assert m["ms"] > 0 and m["ring_error"] >= 0 and m["fovea_psnr"] > 100, mode
    assert view["dither_4"]["roughness"] > view["exact"]["roughness"]   # dither noise is measured
    assert view["native"]["stride"] == 1 and view["native"]["fovea_psnr"] == float("inf")   # (trained at scale 1)
    mip = view["mip_3_0.25_0"]                                           # render_lod_mip, its defaults
    assert mip["ms"] > 0 and mip["fovea_psnr"] > 100 and 0 < mip["rays"] <= 1
    assert mip["roughness"] < view["dither_4"]["roughness"]


def test_bench_lfn_curve_display_and_summary():
    """tools.bench_lfn_curve: the displayed curve holds each ladder size until the next one."""
    import numpy as np

    from tools.bench_lfn_curve import displayed, summary

    p = np.array([10.0, 11.0, 10.5, 12.0, 11.0])          # sizes 4..8
    assert displayed(p, None, 4).tolist() == p.tolist()
    assert displayed(p, [4, 5, 7, 8], 4).tolist() == [10.0, 11.0, 11.0, 12.0, 11.0]
    s = summary(displayed(p, [4, 5, 7, 8], 4))
    assert s["drops_over_0.1dB"] == 1 and s["worst_drop_db"] == -1.0 and s["last_psnr"] == 11.0


def test_per_view_peers_keep_alpha_exact_and_count_it():
    """Views with alpha: a per-view peer codes the colour and keeps the alpha plane exact beside
    it (zlib, as tx version 6 does), its bytes counted; views without alpha are untouched."""
    import numpy as np

    from rlfc.topcodec import alpha_stream

    rng = np.random.default_rng(3)
    rgb = rng.integers(0, 256, (3, 24, 40, 3), dtype=np.uint8)
    alpha = np.zeros((3, 24, 40, 1), np.uint8)
    alpha[:, 6:18, 10:30] = 255
    alpha[:, 6, 10:30] = 97
    for make in (peers.j2k, peers.jxl):
        p = make()
        r = p.run(np.concatenate([rgb, alpha], -1), p.settings[2])
        plain = p.run(rgb, p.settings[2])
        assert r["decoded"].shape == (3, 24, 40, 4) and (r["decoded"][..., 3:] == alpha).all()
        assert (r["decoded"][..., :3] == plain["decoded"].reshape(rgb.shape)).all()
        assert r["bytes"] == plain["bytes"] + sum(len(alpha_stream(a[..., 0])) for a in alpha)
