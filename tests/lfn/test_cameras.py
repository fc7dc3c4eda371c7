"""Free cameras for LFN files (lfn_stream.cameras through LfnRenderer): captured poses render the
captured views, grid positions blend centres, orbits turn about the cameras' common target,
stereo pairs sit ipd apart; bad poses are ParameterErrors."""
import json

import numpy as np
import pytest

from formats.errors import ParameterError
from formats.lfcfile import open_lfc
from lfn_stream import LfnRenderer
from tests.conftest import ROOT

GOLDEN = ROOT / "tests" / "data" / "golden" / "lfn_tiny_rgba8.lfc"


@pytest.fixture(scope="module")
def r():
    return LfnRenderer(open_lfc(GOLDEN), device="cpu")


def test_captured_and_grid_poses_render_the_captured_views(r):
    for row, col in [(0, 0), (1, 2), (3, 3)]:
        assert np.array_equal(r.grid_pose(row, col), r.pose(row, col))
        assert np.array_equal(r.render_pose(r.pose(row, col), 6.5, 1.0), r.render(row, col, 6.5, 1.0))
    p = r.grid_pose(1.5, 2.25)
    assert np.allclose(p[:3, 3], [2.25, -1.5, 0.0]) and np.allclose(p[:3, :3], np.eye(3))
    with pytest.raises(ParameterError):
        r.grid_pose(4, 0)


def test_orbit_turns_about_the_pivot_and_stereo_pairs(r):
    assert np.allclose(r.orbit_pose(1, 1, 0, 0), r.pose(1, 1))
    a = r.orbit_pose(1, 1, 30, 0)
    pivot = np.asarray(r.norm["centre"])           # a planar grid: axes parallel, the pivot falls back
    assert np.isclose(np.linalg.norm(a[:3, 3] - pivot), np.linalg.norm(r.pose(1, 1)[:3, 3] - pivot))
    assert np.allclose(a[:3, :3] @ a[:3, :3].T, np.eye(3))
    left, right = r.stereo_poses(r.pose(2, 2), 0.064)
    assert np.isclose(np.linalg.norm(left[:3, 3] - right[:3, 3]), 0.064)
    assert r.render_pose(left).shape == r.render(2, 2).shape


@pytest.mark.parametrize("bad", [np.eye(3), np.full((4, 4), np.nan), np.zeros((4, 4)), "x"])
def test_bad_poses(r, bad):
    with pytest.raises(ParameterError):
        r.render_pose(bad)


@pytest.mark.parametrize("bad", ["x", float("nan"), True, None])
def test_turns_and_eye_distances_must_be_numbers(r, bad):
    """A yaw, pitch or ipd that is not a finite number: a ParameterError naming it (a string was
    float()'s ValueError, NaN made a NaN pose)."""
    for call, name in ((lambda: r.turn_pose(r.pose(1, 1), bad), "yaw"), (lambda: r.orbit_pose(1, 1, 10, bad), "pitch"),
                       (lambda: r.stereo_poses(r.pose(1, 1), bad), "ipd")):
        with pytest.raises(ParameterError, match=f"{name} must be a finite number"):
            call()


# -- lfcodec render on LFN files ------------------------------------------------------------
GOLDEN3 = ROOT / "tests" / "data" / "golden" / "lfn3_tiny_rgba8.lfc"


def _render_cli(tmp_path, *args, src=GOLDEN3):
    from formats.cli import main
    from formats.imageio import read_image

    out = tmp_path / "out.png"
    assert main(["render", str(src), str(out), "--quiet", "--device", "cpu", *args]) == 0
    return read_image(out)


def test_cli_renders_lfn_cameras(tmp_path):
    """lfcodec render on a light field network: the default camera is the captured view nearest
    the grid centre; --at, --pose (JSON, a transforms.json frame, 16 numbers), --turn, --level,
    --scale and --stereo give the pixels the library gives for the same camera."""
    r3 = LfnRenderer(open_lfc(GOLDEN3), device="cpu")
    full = r3.neurons

    def px(pose, neurons=full, scale=1.0):
        return r3.to_pixels(r3.render_pose(pose, neurons, scale))

    assert np.array_equal(_render_cli(tmp_path), px(r3.pose(2, 2)))
    assert np.array_equal(_render_cli(tmp_path, "--at", "1.5,0.25"), px(r3.grid_pose(1.5, 0.25)))
    pose = r3.orbit_pose(1, 3, 20, -5)
    (tmp_path / "p.json").write_text(json.dumps(pose.tolist()))
    (tmp_path / "frame.json").write_text(json.dumps({"file_path": "x", "transform_matrix": pose.tolist()}))
    (tmp_path / "p.txt").write_text("\n".join(" ".join(repr(v) for v in row) for row in pose.tolist()))
    for f in ("p.json", "frame.json", "p.txt"):
        assert np.array_equal(_render_cli(tmp_path, "--pose", str(tmp_path / f)), px(pose))
    turned = r3.turn_pose(r3.pose(0, 1), 30, 10)
    assert np.allclose(turned, r3.orbit_pose(0, 1, 30, 10))
    got = _render_cli(tmp_path, "--at", "0,1", "--turn", "30,10", "--level", "2.5", "--scale", "0.5")
    assert np.array_equal(got, px(turned, full - 2.5, 0.5)) and got.shape[:2] == (14, 18)
    left, right = r3.stereo_poses(r3.pose(2, 2), 0.25)
    pair = _render_cli(tmp_path, "--stereo", "0.25")
    assert pair.shape == (29, 74, 4) and np.array_equal(pair, np.concatenate([px(left), px(right)], 1))
    assert not np.array_equal(pair[:, :37], pair[:, 37:])
    # --gaze: the foveation map drawn by render_pose_lod_mip (--fovea sets its radii), per eye
    fov = r3.foveation_map((9.0, 7.0), 0.05, 0.4, dither=False, scale=2.0)
    want = r3.to_pixels(r3.render_pose_lod_mip(r3.pose(2, 2), fov))
    assert np.array_equal(_render_cli(tmp_path, "--gaze", "9,7", "--fovea", "0.05,0.4", "--scale", "2"), want)
    assert not np.array_equal(want, px(r3.pose(2, 2), scale=2.0))
    # --fast: render_pose(native=True); the golden file has no display ladders (trained at its
    # views' scale), so every pixel is rendered as without it
    assert np.array_equal(_render_cli(tmp_path, "--fast"), px(r3.pose(2, 2)))
    fov = r3.foveation_map((20.0, 14.0), dither=False)
    assert np.array_equal(_render_cli(tmp_path, "--fast", "--gaze", "20,14"),
                          r3.to_pixels(r3.render_pose_lod_mip(r3.pose(2, 2), fov, native=True)))
    fov = r3.foveation_map((20.0, 14.0), dither=False)
    eyes = [r3.to_pixels(r3.render_pose_lod_mip(p, fov)) for p in (left, right)]
    assert np.array_equal(_render_cli(tmp_path, "--gaze", "20,14", "--stereo", "0.25"), np.concatenate(eyes, 1))


def test_cli_lfn_quilt_path_and_partial_prefix(tmp_path):
    """A quilt turns the camera across a 35° cone (bottom-left first); --path turn:N turns it a
    full circle; a byte prefix renders with --partial and --pose, as the smaller network."""
    from formats.cli import main
    from formats.imageio import read_image

    r3 = LfnRenderer(open_lfc(GOLDEN3), device="cpu")
    q = _render_cli(tmp_path, "--quilt", "3x2", "--scale", "0.5")
    assert q.shape == (2 * 14, 3 * 18, 4)
    first = r3.to_pixels(r3.render_pose(r3.turn_pose(r3.pose(2, 2), -17.5), r3.neurons, 0.5))
    assert np.array_equal(q[14:, :18], first)                        # bottom-left: the first view
    seq = tmp_path / "seq"
    assert main(["render", str(GOLDEN3), str(seq), "--path", "turn:4", "--at", "1,1", "--quiet"]) == 0
    frames = sorted(seq.iterdir())
    assert len(frames) == 4
    assert np.array_equal(read_image(frames[0]), r3.to_pixels(r3.render_pose(r3.pose(1, 1), r3.neurons, 1.0)))
    assert np.array_equal(read_image(frames[2]), r3.to_pixels(r3.render_pose(r3.turn_pose(r3.pose(1, 1), 180),
                                                                               r3.neurons, 1.0)))
    # a prefix ending inside lfn.steps: the smaller network, the camera from --pose
    c = r3.file.container
    cut = c.info("lfn.steps").offset + 2 * c.info("lfn.steps").chunk_size
    pre = tmp_path / "prefix.lfc"
    pre.write_bytes(GOLDEN3.read_bytes()[:cut])
    small = LfnRenderer(open_lfc(pre, partial=True), device="cpu")
    assert small.neurons < r3.neurons
    (tmp_path / "p.json").write_text(json.dumps(r3.pose(3, 0).tolist()))
    got = _render_cli(tmp_path, "--partial", "--pose", str(tmp_path / "p.json"), src=pre)
    assert np.array_equal(got, r3.to_pixels(r3.render_pose(r3.pose(3, 0), small.neurons, 1.0)))


@pytest.mark.parametrize("args,needle", [
    (["--focus", "1"], "refocus an RLFC grid"),
    (["--at", "1,1", "--pose", "P"], "give one"),
    (["--turn", "1,2,3"], "YAW[,PITCH]"),
    (["--scale", "0"], "--scale"),
    (["--stereo", "-1"], "eye distance"),
    (["--level", "9"], "level must be within"),
    (["--pose", "P", "--path", "orbit:3"], "does not go with"),
    (["--quilt", "2x1", "--stereo", "0.1"], "give one"),
    (["--device", "nonsense"], "not a device"),
    (["--pose", "BAD"], "16 finite numbers"),
    (["--at", "9,9"], "outside"),
    (["--gaze", "1"], "--gaze must be 2"),
    (["--gaze", "1,nan"], "--gaze must be 2"),
    (["--gaze", "1,1", "--level", "1"], "give --gaze or --level"),
    (["--fovea", "0.1,0.3"], "give --gaze"),
    (["--gaze", "1,1", "--fovea", "0.5,0.1"], "inner and outer"),
])
def test_cli_lfn_render_errors_are_one_line(tmp_path, capsys, args, needle):
    from formats.cli import main

    (tmp_path / "P").write_text(json.dumps(np.eye(4).tolist()))
    (tmp_path / "BAD").write_text("1 2 3")
    args = [str(tmp_path / a) if a in ("P", "BAD") else a for a in args]
    assert main(["render", str(GOLDEN3), str(tmp_path / "o.png"), *args]) == 2
    err = capsys.readouterr().err
    assert needle in err and err.count("\n") == 1 and "Traceback" not in err


def test_cli_lfn_options_on_rlfc_files_and_prefix_without_partial(tmp_path, capsys):
    from formats.cli import main

    rl = ROOT / "tests" / "data" / "golden" / "rlfc_dcp_lossy_rgb8.lfc"
    for args, needle in ((["--level", "1"], "light field network files"), (["--stereo", "0.1"], "network files"),
                         (["--gaze", "4,4"], "network files"), (["--path", "turn:3"], "--path turn")):
        out = tmp_path / ("seq" if "--path" in args else "o.png")
        assert main(["render", str(rl), str(out), *args]) == 2
        err = capsys.readouterr().err
        assert needle in err and err.count("\n") == 1
    pre = tmp_path / "prefix.lfc"
    pre.write_bytes(GOLDEN3.read_bytes()[:1200])
    assert main(["render", str(pre), str(tmp_path / "o.png")]) == 2
    assert "--partial" in capsys.readouterr().err
    assert main(["render", str(pre), str(tmp_path / "o.png"), "--partial"]) == 2     # cameras are past the prefix
    assert "--pose FILE" in capsys.readouterr().err
    for args in ([str(tmp_path / "dec")], [str(tmp_path / "dec"), "--view", "0,0"]):    # nor the captured views
        assert main(["decode", str(pre), *args, "--partial"]) == 2
        err = capsys.readouterr().err
        assert "render --partial --pose" in err and err.count("\n") == 1 and not (tmp_path / "dec").exists()
    assert main(["info", str(pre), "--partial"]) == 0
    assert "in this prefix" in capsys.readouterr().out


def test_cli_info_partial_lists_the_sections_of_an_rlfc_prefix(tmp_path, capsys):
    """An RLFC file needs every section to open: ``info --partial`` on a prefix still lists what
    the prefix holds and says it does not open; without ``--partial`` it is a one-line error."""
    from formats.cli import main

    blob = (ROOT / "tests" / "data" / "golden" / "rlfc_tx2_lossy_rgb8.lfc").read_bytes()
    pre = tmp_path / "prefix.lfc"
    pre.write_bytes(blob[:len(blob) - 200])
    assert main(["info", str(pre), "--partial"]) == 0
    out = capsys.readouterr().out
    assert "does not open as a light field" in out and "tx.blocks" in out and "in this prefix" in out
    assert main(["info", str(pre), "--partial", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["decoder"]["decodable"] is False
    assert main(["info", str(pre)]) == 2
    err = capsys.readouterr().err
    assert "--partial" in err and err.count("\n") == 1


def test_camera_rays_against_plain_geometry():
    """camera_rays (written out per component) against the textbook construction in float64:
    direction R·K⁻¹(x, y, 1) in OpenGL axes, normalized, moment o × d of the normalized origin;
    a subset ``at`` gives exactly the grid's rows; a non-finite camera is an error."""
    from lfn_stream.rays import camera_rays
    rng = np.random.default_rng(3)
    for _ in range(5):
        q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        c2w = np.eye(4)
        c2w[:3, :3], c2w[:3, 3] = q, rng.normal(size=3) * 3
        focal, principal = rng.uniform(20, 80, 2), rng.uniform(5, 20, 2)
        centre, radius = rng.normal(size=3), float(rng.uniform(0.5, 4))
        H, W, scale = 24, 31, 1.5
        rays = camera_rays(c2w, focal, principal, H, W, scale, centre, radius)
        h, w = round(H * scale), round(W * scale)
        assert rays.shape == (h, w, 6) and rays.dtype == np.float32
        ys, xs = np.mgrid[0:h, 0:w] + 0.5
        sy, sx = h / H, w / W                      # output pixels per view pixel
        cam = np.stack([(xs - principal[0] * sx) / (focal[0] * sx),
                        -(ys - principal[1] * sy) / (focal[1] * sy), -np.ones_like(xs)], -1)
        d = np.einsum("ij,hwj->hwi", q, cam)
        d /= np.sqrt((d ** 2).sum(-1, keepdims=True))
        m = np.cross((c2w[:3, 3] - centre) / radius, d)
        np.testing.assert_allclose(rays, np.concatenate([d, m], -1), rtol=0, atol=1e-6 * (1 + np.abs(m).max()))
        at = rng.integers(0, h * w, 50)
        assert np.array_equal(camera_rays(c2w, focal, principal, H, W, scale, centre, radius, at=at),
                              rays.reshape(-1, 6)[at])
    bad = np.eye(4)
    bad[0, 3] = np.inf
    with pytest.raises(ParameterError):
        camera_rays(bad, (10, 10), (5, 5), 8, 8)
