"""The hard variants of ``tools.unseen`` do what their docstrings say, deterministically, on a
small synthetic grid: a gain per view (exposure), a gain per view and channel (white balance), a
sub-pixel shift per view (jitter), noise per view, a rotation or a scale per view, JPEG
artefacts per view."""
import numpy as np

from tools.unseen import exposed, jittered, jpeg_sourced, noisy, rotated, white_balanced, zoomed


def _grid():
    rng = np.random.default_rng(0)
    return rng.integers(60, 190, (3, 4, 16, 20, 3)).astype(np.uint8)


def _gains(out, v):
    """Least-squares gain of out against v, per view and channel: (rows, cols, C)."""
    a, b = v.astype(np.float64), out.astype(np.float64)
    return (a * b).sum((2, 3)) / (a * a).sum((2, 3))


def test_exposure_is_one_gain_per_view_and_white_balance_one_per_channel():
    v = _grid()
    e, w = exposed(v), white_balanced(v)
    for out in (e, w):
        assert out.dtype == np.uint8 and out.shape == v.shape
    ge, gw = _gains(e, v), _gains(w, v)
    assert np.abs(ge - ge[..., :1]).max() < 0.01                       # the channels share the view's gain
    assert 0.89 < ge.min() and ge.max() < 1.11 and ge.std() > 0.02
    assert np.abs(gw - gw[..., :1]).max() > 0.02                       # the channels differ
    assert 0.93 < gw.min() and gw.max() < 1.07
    assert (white_balanced(v) == w).all() and (exposed(v) == e).all()   # seeded


def test_jitter_and_noise_keep_the_grid_and_are_seeded():
    v = _grid()
    j, n = jittered(v), noisy(v, 3.0)
    assert j.shape == n.shape == v.shape and j.dtype == n.dtype == np.uint8
    assert (jittered(v) == j).all() and (noisy(v, 3.0) == n).all()
    assert 2.0 < (n.astype(float) - v).std() < 4.0
    assert not (j == v).all() and np.abs(j.astype(float) - v).mean() < 40


def _blobs():
    """A (3, 3, 160, 160, 3) grid of one view: four Gaussian blobs 60 px from the centre."""
    y, x = np.mgrid[0:160, 0:160].astype(np.float64)
    img = sum(200 * np.exp(-((x - 79.5 - dx) ** 2 + (y - 79.5 - dy) ** 2) / 18)
              for dy, dx in ((0, 60), (60, 0), (0, -60), (-60, 0)))
    v = np.rint(20 + img).astype(np.uint8)[..., None].repeat(3, -1)
    return np.broadcast_to(v, (3, 3, 160, 160, 3)).copy()


def _similarity(out):
    """Per view, the (angle in degrees, scale) that carries the blobs' centroids from where
    :func:`_blobs` puts them (about the view's centre): (9, 2)."""
    y, x = np.mgrid[0:160, 0:160].astype(np.float64)
    got = []
    for o in out.reshape(-1, 160, 160, 3):
        w = np.maximum(o[..., 0].astype(np.float64) - 20, 0)
        ang, sc = [], []
        for dy, dx in ((0, 60), (60, 0), (0, -60), (-60, 0)):
            m = w * ((np.abs(x - 79.5 - dx) < 12) & (np.abs(y - 79.5 - dy) < 12))
            cy, cx = (m * y).sum() / m.sum() - 79.5, (m * x).sum() / m.sum() - 79.5
            ang.append(np.degrees(np.arctan2(cy, cx) - np.arctan2(dy, dx)))
            sc.append(np.hypot(cy, cx) / 60)
        got.append((np.mean((np.array(ang) + 180) % 360 - 180), np.mean(sc)))
    return np.array(got)


def test_rotation_and_zoom_are_one_warp_per_view_within_their_reach():
    v = _blobs()
    r, z = rotated(v), zoomed(v)
    assert r.shape == z.shape == v.shape and r.dtype == z.dtype == np.uint8
    assert (rotated(v) == r).all() and (zoomed(v) == z).all()          # seeded
    assert np.abs(_similarity(v) - [0, 1]).max() < 0.01               # (the measure itself)
    sr, sz = _similarity(r), _similarity(z)
    assert np.abs(sr[:, 0]).max() <= 0.5 + 0.05 and sr[:, 0].std() > 0.1   # its own angle per view, within ±0.5°
    assert np.abs(sr[:, 1] - 1).max() < 0.001                                # ... and no scale
    assert np.abs(sz[:, 1] - 1).max() <= 0.006 + 0.001 and sz[:, 1].std() > 0.001   # its own scale, 1 ± 0.6%
    assert np.abs(sz[:, 0]).max() < 0.05                                     # ... and no rotation


def test_jpeg_sourced_views_carry_their_own_block_artefacts():
    rng = np.random.default_rng(3)
    v = np.clip(_blobs().astype(np.int64) + rng.integers(-20, 21, (3, 3, 160, 160, 3)), 0, 255).astype(np.uint8)
    j = jpeg_sourced(v)
    assert j.shape == v.shape and j.dtype == np.uint8 and (jpeg_sourced(v) == j).all()
    err = j.astype(np.float64) - v
    assert 1.0 < np.sqrt((err ** 2).mean()) < 12.0                     # lossy, not ruinous at quality 85
    assert not (err[0, 0] == err[0, 1]).all()                           # each view its own artefacts


def test_saved_scenes_read_back_as_grids(tmp_path):
    """``--save-scenes`` writes each variant as a scene the readers take as it is (views and a
    scene.json saying where it comes from), 8-bit RGB and 16-bit grey alike: the same views,
    grid and focal as the variant in memory."""
    from formats.scenes import read_scene
    from tools.unseen import _grid, save_scene

    rng = np.random.default_rng(1)
    for name, views in (("rgb8", rng.integers(0, 256, (2, 3, 12, 16, 3)).astype(np.uint8)),
                        ("grey16", rng.integers(0, 65536, (3, 2, 10, 14, 1)).astype(np.uint16))):
        lf = _grid(views, f"a test variant {name}")
        save_scene(tmp_path / name, lf)
        back = read_scene(tmp_path / name)
        assert back.layout == "grid" and (back.rows, back.cols) == views.shape[:2]
        assert back.views.dtype == views.dtype and (back.views == views).all()
        assert tuple(back.focal) == tuple(lf.focal)
        assert f"a test variant {name}" in back.meta.get("source", "")
