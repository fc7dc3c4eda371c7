"""Free cameras for LFN files (lfn_stream.cameras through LfnRenderer): captured poses render the
captured views, grid positions blend centres, orbits turn about the cameras' common target,
stereo pairs sit ipd apart; bad poses are ParameterErrors."""
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
