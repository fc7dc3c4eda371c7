"""Smoke runs of the decode-speed and remote benchmarks on a tiny grid: every figure they report
is produced and sane (the numbers themselves belong in BENCHMARKS.md, not in tests)."""
import json

import numpy as np
import pytest

from formats.cli import main as cli
from formats.scenes import write_views
from tests.rlfc.helpers import smooth_lf
from tools import bench_decode, bench_remote


def _tiny(tmp_path):
    lf = smooth_lf(rows=3, cols=3, h=32, w=40)
    write_views(tmp_path / "data" / "tiny", lf.views)
    (tmp_path / "data" / "tiny" / "scene.json").write_text(json.dumps(
        {"layout": "grid", "rows": 3, "cols": 3, "views": "r{row:02d}_c{col:02d}.png"}))
    f = tmp_path / "tiny.lfc"
    assert cli(["encode", str(tmp_path / "data" / "tiny"), str(f), "--target-psnr", "36", "--quiet"]) == 0
    return f


def test_bench_decode_worker_reports_every_figure(tmp_path, monkeypatch):
    f = _tiny(tmp_path)
    monkeypatch.setattr(bench_decode.tempfile, "gettempdir", lambda: str(tmp_path))
    peer = bench_decode._prepare_peer(f, tmp_path / "data", tmp_path)
    assert len(peer["views"]) == 6 and peer["psnr_j2k"] > 30
    r = bench_decode._worker(str(f), peer["file"], 0, 300, 20, [1, 2])
    for k in ("open_s", "batch_us_t1", "batch_us_t2", "batch_warm_us_t1", "batch_warm_us_t2", "all_s_t1",
              "j2k_all_s_t2", "gather_us", "view_s", "j2k_view_s", "view_seq_s", "j2k_view_seq_s", "fresh_view_s",
              "j2k_fresh_view_s", "fresh_all_s"):
        assert r[k] > 0, k
    assert len(r["single_us"]) == len(r["single_warm_us"]) == 20
    s = bench_decode._summarize([r, r], [1, 2])
    assert s["batch_mpix_t2"] > 0 and s["batch_warm_mpix_t1"] > 0
    assert s["view_vs_j2k"] > 0 and s["view_seq_vs_j2k"] > 0 and np.isfinite(s["single_p99_us"])
    assert s["fresh_view_vs_j2k"] > 0 and s["fresh_all_vs_j2k"] > 0
    assert 0 < s["single_warm_p50_us"] <= s["single_warm_p99_us"]
    table = bench_decode._table({"tiny": {"new": s}}, "new", [1, 2])
    assert table[2].startswith("| tiny |")


def test_bench_remote_renders_frames_over_http(tmp_path):
    f = _tiny(tmp_path)
    res = bench_remote.run(f, latency_ms=0.0, n_blocks=5, cache_mib=1.0, page=512, frames=3)
    assert res["frames"] == 3 and res["frame_requests_first"] >= 0 and res["frame_ms_p50"] > 0
    # (a tiny file is fetched whole at open: its blocks share one checksum chunk)
    assert res["open_and_first_frame_s"] > 0 and 0 < res["render_wire_bytes"] <= res["bytes"] + 512
    json.dumps(res)


def test_bench_render_reports_quality_and_speed_on_each_device(tmp_path):
    from tools import bench_render

    lf = smooth_lf(rows=5, cols=5, h=32, w=40)
    write_views(tmp_path / "tiny", lf.views)
    (tmp_path / "tiny" / "scene.json").write_text(json.dumps(
        {"layout": "grid", "rows": 5, "cols": 5, "views": "r{row:02d}_c{col:02d}.png"}))
    r = bench_render.bench_scene(str(tmp_path / "tiny"), 36.0, ("numpy", "cpu"))
    assert r["encoded_views"] == "3x3" and set(r["psnr"]) == {"render", "render_fast", "nearest", "blend"}
    for k in ("warm_fps", "warm_fps_fast", "warm_fps_cpu", "warm_fps_fast_cpu"):
        assert r[k] > 0, k
    assert r["max_plane_diff_cpu"] < 1e-3 and r["max_plane_diff_fast_cpu"] < 1e-3
    # frame times of an encoded file, and the mid-view check (a shifted scene: shifting must win)
    from rlfc import encode
    from tools.common import open_encoded

    (tmp_path / "f.lfc").write_bytes(open_encoded(lf, encode(lf, profile="tx", step=2.0))[1])
    s = bench_render.speed_file(str(tmp_path / "f.lfc"), ("numpy",))
    assert s["views"] == "5x5" and s["warm_fps"] > 0 and s["blocks_per_frame"] > 0
    m = bench_render.midview_check(str(tmp_path / "tiny"), 1)
    fr = m["bicubic_fraction_of_shift"]
    assert m["view_step"] == 1 and set(fr) == {"0.0", "0.25", "0.5", "0.75", "1.0"}
    assert fr["1.0"] == m["shifted_bicubic"] and fr["0.0"] == m["blend_no_shift"]   # integer taps: exact
    assert fr["1.0"] > fr["0.5"] > fr["0.0"]        # a scene of integer shifts: the full shift is exact


def test_bench_render_ab_compares_two_checkouts_in_one_process(tmp_path):
    """The side-by-side renderer benchmark against a checkout (here this one, imported a second
    time as rlfc_old): both versions render the same frames, times and ratios reported."""
    from pathlib import Path

    from rlfc import encode
    from tools import bench_render_ab
    from tools.common import open_encoded

    lf = smooth_lf(rows=3, cols=3, h=32, w=40)
    (tmp_path / "f.lfc").write_bytes(open_encoded(lf, encode(lf, profile="tx", step=2.0))[1])
    assert bench_render_ab.main([str(tmp_path / "f.lfc"), "--old", str(Path(__file__).parents[2]),
                                 "--out", str(tmp_path / "ab.json")]) == 0
    res = json.loads((tmp_path / "ab.json").read_text())["files"]["f"]
    for k in ("robust", "fast"):
        assert res[k]["max_pixel_diff"] == 0 and res[k]["new"] > 0 and res[k]["old"] > 0
        assert res[k]["ratio_new_old"] == round(res[k]["new"] / res[k]["old"], 3)
    with pytest.raises(SystemExit):
        bench_render_ab.main([str(tmp_path / "f.lfc"), "--old", str(tmp_path)])


def test_bench_lfn_runs_end_to_end(tmp_path):
    """The LFN benchmark's command line (options, training, file, prefix check, table) on a tiny
    grid: every level is reported with finite PSNR and the bytes it needs rise with the level."""
    from tools import bench_lfn

    lf = smooth_lf(rows=3, cols=3, h=16, w=16)
    write_views(tmp_path / "tiny", lf.views)
    (tmp_path / "tiny" / "scene.json").write_text(json.dumps(
        {"layout": "grid", "rows": 3, "cols": 3, "views": "r{row:02d}_c{col:02d}.png"}))
    assert bench_lfn.main([str(tmp_path / "tiny"), "--out", str(tmp_path / "o"), "--resolution", "0", "--depth", "2",
                           "--min-neurons", "4", "--max-neurons", "8", "--steps", "5", "--batch", "64",
                           "--no-single-scale"]) == 0
    r = json.loads((tmp_path / "o" / "lfn_results.json").read_text())
    assert r["config"]["min_neurons"] == 4 and r["config"]["max_neurons"] == 8
    assert all(np.isfinite(x["psnr"]) for x in r["lod"])
    assert [x["bytes"] for x in r["lod"]] == sorted(x["bytes"] for x in r["lod"])


def test_bench_rate_speed_reports_a_curve_per_grid(tmp_path, monkeypatch):
    """The rate/speed curve: each target encoded by the command line, measured by bench_decode
    against its own JPEG 2000 peer (peers are cached by file content: the two files of one scene
    get two peers), with the coded-block share beside the speeds."""
    from tools import bench_rate_speed

    _tiny(tmp_path)
    monkeypatch.setattr(bench_decode.tempfile, "gettempdir", lambda: str(tmp_path))
    out = tmp_path / "rs"
    assert bench_rate_speed.main(["tiny", "--data", str(tmp_path / "data"), "--targets", "34,44", "--rounds", "1",
                                  "--batch", "200", "--single", "10", "--threads", "1", "--out", str(out)]) == 0
    rows = json.loads((out / "rate_speed.json").read_text())["rows"]
    assert [r["target"] for r in rows] == [34.0, 44.0]
    lo, hi = rows
    assert lo["psnr"] >= 34 and hi["psnr"] >= 44 and hi["bpp"] > lo["bpp"]
    assert hi["j2k_bytes"] > lo["j2k_bytes"]                 # each file's own peer, at its own PSNR
    for r in rows:
        assert (r["coded_share"] is None or 0 <= r["coded_share"] <= 1) and r["views"] == 9 and r["key_views"] >= 1
        assert r["speed"]["batch_mpix_t1"] > 0 and r["j2k_view_mpix"] > 0
    assert "| tiny | 44 |" in (out / "rate_speed.md").read_text()


def test_bench_gpu_decode_times_every_way_of_parsing(tmp_path, capsys):
    """The GPU decode benchmark runs on the CPU device too: each way of parsing asserted equal to
    numpy, each timed."""
    from tools import bench_gpu_decode

    f = _tiny(tmp_path)
    assert bench_gpu_decode.main([str(f), "--device", "cpu", "--counts", "200", "--parse", "host,steps,auto"]) == 0
    out = capsys.readouterr().out
    assert out.count("equal to numpy") == 3
    for w in ("numpy", "torch host", "torch steps", "torch auto"):
        assert f"{w} " in out, w
