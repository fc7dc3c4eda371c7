"""Camera paths (issue 16): presets and path files, `lfcodec render --path` to PNG frames and
to MP4 (when ffmpeg is present), typed errors for bad paths."""
import json
import shutil

import numpy as np
import pytest

from formats.cli import main
from formats.errors import ParameterError, UnsupportedError
from formats.imageio import read_image
from rlfc import encode
from formats.campath import MAX_FRAMES, orbit, read_path, sweep
from tests.rlfc.helpers import open_encoded, smooth_lf


@pytest.fixture(scope="module")
def grid(tmp_path_factory):
    lf = smooth_lf(rows=3, cols=4, h=24, w=30)
    d, blob = open_encoded(lf, encode(lf, profile="tx", step=4.0))
    p = tmp_path_factory.mktemp("path") / "g.lfc"
    p.write_bytes(blob)
    return d, p


def test_presets_stay_inside_the_grid():
    o = orbit(3, 4, 12)
    assert o.shape == (12, 4) and np.isnan(o[:, 2]).all() and (o[:, 3] == 0).all()
    assert (o[:, 0] >= 0).all() and (o[:, 0] <= 2).all() and (o[:, 1] >= 0).all() and (o[:, 1] <= 3).all()
    s = sweep(3, 4, 7)
    assert s[0, 1] == 0 and s[3, 1] == 3 and s[-1, 1] == 0 and (s[:, 0] == 1).all()
    assert read_path("orbit:5", 3, 4).shape == (5, 4) and read_path("sweep", 3, 4).shape[0] == 60


def test_path_files_text_and_json(tmp_path):
    t = tmp_path / "p.txt"
    t.write_text("# s,t,focus,aperture\n0.5,1.5\n1,2,0.25\n\n1,2,,0.5  # maps, aperture\n")
    cams = read_path(str(t), 3, 4)
    assert cams.shape == (3, 4)
    assert np.isnan(cams[0, 2]) and cams[1, 2] == 0.25 and np.isnan(cams[2, 2]) and cams[2, 3] == 0.5
    j = tmp_path / "p.json"
    j.write_text(json.dumps([[0, 0], [1, 1, 0.5, 1.0]]))
    assert read_path(str(j), 3, 4).tolist()[1] == [1, 1, 0.5, 1.0]


@pytest.mark.parametrize("content", ["", "abc", "1", "1,2,3,4,5", "nan,1", "1,inf", "1,1,0,-1", "[1, 2]",
                                     "[[1]]", "[[true, 1]]", "[[1, 2]", "1,1,inf"])
def test_bad_path_files_are_parameter_errors(tmp_path, content):
    p = tmp_path / "bad.txt"
    p.write_text(content)
    with pytest.raises(ParameterError):
        read_path(str(p), 3, 4)


@pytest.mark.parametrize("spec", ["orbit:0", f"orbit:{MAX_FRAMES + 1}", "circle", "", "sweep:-3", "orbit:1.5"])
def test_bad_specs_are_parameter_errors(spec):
    with pytest.raises(ParameterError):
        read_path(spec, 3, 4)


def test_cli_path_to_png_frames_equals_the_renderer(grid, tmp_path):
    d, f = grid
    out = tmp_path / "frames"
    assert main(["render", str(f), str(out), "--path", "sweep:3", "--quiet"]) == 0
    frames = sorted(out.iterdir())
    assert [x.name for x in frames] == ["frame_00000.png", "frame_00001.png", "frame_00002.png"]
    ren = d.renderer()
    for x, img in zip(frames, ren.render_path(sweep(3, 4, 3))):
        assert (read_image(x) == img).all()


def test_cli_path_errors(grid, tmp_path, capsys):
    _, f = grid
    p = tmp_path / "far.txt"
    p.write_text("1,1\n9,1\n")                                          # the second camera is outside
    q = tmp_path / "focus.txt"
    q.write_text("1,1\n1,1.5,2,1\n1,2,1e30,1\n")                      # the third camera's focus is absurd
    for argv in (["--path", str(p)], ["--path", str(q)], ["--path", "orbit:3", "--focus", "1e9", "--aperture", "1"],
                 ["--path", "orbit:3", "--at", "1,1"], ["--path", "orbit:3", "--quilt", "2x1"],
                 ["--path", "orbit:3", "--fps", "0"], ["--path", "nope"]):
        assert main(["render", str(f), str(tmp_path / "seq"), *argv, "--quiet"]) == 2, argv
        assert capsys.readouterr().err.strip()
    assert not (tmp_path / "seq").exists()                            # nothing written before the check
    assert main(["render", str(f), str(tmp_path / "x.png"), "--path", "orbit:3", "--quiet"]) == 2


def test_mp4_without_ffmpeg_is_a_clear_error(grid, tmp_path, monkeypatch, capsys):
    _, f = grid
    monkeypatch.setattr(shutil, "which", lambda name: None)
    assert main(["render", str(f), str(tmp_path / "o.mp4"), "--path", "orbit:3", "--quiet"]) == 2
    assert "ffmpeg" in capsys.readouterr().err
    assert not (tmp_path / "o.mp4").exists()
    from formats.video import SequenceWriter

    with pytest.raises(UnsupportedError):
        SequenceWriter(tmp_path / "o.mp4")


@pytest.mark.skipif(shutil.which("ffmpeg") is None, reason="ffmpeg is not installed (apt-get install ffmpeg)")
def test_cli_path_to_mp4(grid, tmp_path):
    _, f = grid
    out = tmp_path / "o.mp4"
    assert main(["render", str(f), str(out), "--path", "orbit:8", "--fps", "12", "--quiet"]) == 0
    data = out.read_bytes()
    assert len(data) > 200 and b"ftyp" in data[:64]
    assert [x.name for x in tmp_path.iterdir()] == ["o.mp4"]            # no temporary file left


def test_path_frames_never_mix_with_an_earlier_sequence(grid, tmp_path, capsys):
    """A folder that holds frames already: refused (a shorter second run would leave the first
    run's last frames in the sequence); --overwrite replaces them and removes the earlier
    sequence's frames past the new end; other files in the folder are left alone."""
    _, f = grid
    out = tmp_path / "frames"
    assert main(["render", str(f), str(out), "--path", "orbit:5", "--quiet"]) == 0
    (out / "notes.txt").write_text("mine")
    before = (out / "frame_00000.png").read_bytes()
    assert main(["render", str(f), str(out), "--path", "sweep:3", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "holds 5 frames of an earlier sequence (frame_00000.png" in err and "--overwrite" in err
    assert (out / "frame_00000.png").read_bytes() == before and len(list(out.glob("frame_*.png"))) == 5
    assert main(["render", str(f), str(out), "--path", "sweep:3", "--overwrite", "--quiet"]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["frame_00000.png", "frame_00001.png", "frame_00002.png",
                                                     "notes.txt"]


def test_png_frames_written_in_the_background_fail_loudly(tmp_path, failing_write):
    """PNG frames go to a writer thread; every frame lands in order, and a write that fails
    raises its typed error at the next write or at close, never silently."""
    import numpy as np
    import pytest

    import formats.imageio as io
    from formats.errors import SceneError
    from formats.video import SequenceWriter, frame_files

    frames = [np.full((8, 10, 3), 20 * i, np.uint8) for i in range(5)]
    with SequenceWriter(tmp_path / "ok") as w:
        for f in frames:
            w.write(f)
    got = frame_files(tmp_path / "ok")
    assert [p.name for p in got] == [f"frame_{i:05d}.png" for i in range(5)]
    assert all((io.read_image(p) == f).all() for p, f in zip(got, frames))
    failing_write(io, "frame_00002.png")
    with pytest.raises(SceneError, match="frame_00002"):
        with SequenceWriter(tmp_path / "bad") as w:
            for f in frames:
                w.write(f)
