"""Novel views (issue 16): disparity-compensated interpolation from the compressed file, checked
by leaving views out — a synthetic grid with known parallax encoded with every second view, the
missing views rendered and compared with the true ones, against the nearest view and plain
blending; exact at captured positions; refocus, quilts, the CLI and typed errors."""
from pathlib import Path

import numpy as np
import pytest

from formats.cli import main
from formats.errors import ParameterError
from formats.metrics import psnr_rgb
from rlfc import encode
from tests.rlfc.helpers import make_lf, open_encoded


@pytest.fixture(scope="module")
def leave_out():
    rng = np.random.default_rng(0)
    base = rng.random((80, 120, 3))
    k = np.ones(3) / 3
    for ax in (0, 1):
        base = np.apply_along_axis(lambda m: np.convolve(m, k, mode="same"), ax, base)
    base = (base - base.min()) / np.ptp(base)
    full = np.zeros((5, 5, 40, 48, 3), np.uint8)           # 2 px of parallax per view step
    for r in range(5):
        for c in range(5):
            full[r, c] = np.rint(base[2 * r + 10:2 * r + 50, 2 * c + 20:2 * c + 68] * 255)
    lf = make_lf(np.ascontiguousarray(full[::2, ::2]))     # every second view is encoded
    d, blob = open_encoded(lf, encode(lf, profile="tx", step=2.0))
    return full, d, blob


def test_rendered_missing_views_beat_nearest_and_blending(leave_out):
    full, d, _ = leave_out
    ren = d.renderer()
    for (s, t), (r, c) in (((0.5, 0.5), (1, 1)), ((0, 0.5), (0, 1)), ((1.5, 1), (3, 2))):
        img = ren.render(s, t)
        near = d.decode_view(int(round(s)), int(round(t)))
        blend = ((d.decode_view(int(np.floor(s)), int(np.floor(t))).astype(float)
                  + d.decode_view(int(np.ceil(s)), int(np.ceil(t)))) / 2).astype(np.uint8)
        p = psnr_rgb(full[r, c], img)
        assert p > 30 and p > psnr_rgb(full[r, c], near) + 8 and p > psnr_rgb(full[r, c], blend) + 8


def test_captured_positions_are_the_decoded_views_and_blocks_are_cached(leave_out):
    _, d, _ = leave_out
    ren = d.renderer(cache_mib=64)
    assert (ren.render(1, 2) == d.decode_view(1, 2)).all()
    ren.render(0.5, 0.5)
    decoded = ren.blocks_decoded
    ren.render(0.5, 0.5)                               # a warm cache decodes nothing again
    assert ren.blocks_decoded == decoded and ren.blocks_requested > decoded


def test_a_renderer_asks_malloc_to_keep_freed_blocks_unless_told_not_to(leave_out, monkeypatch):
    """Frame after frame, a renderer's large temporaries are freed and allocated again: it asks
    formats.heap.keep_freed (as ``lfcodec render`` does) so that they are reused rather than
    mapped and faulted in afresh; ``keep_freed=False`` leaves malloc alone. The frames are the
    same either way."""
    import formats.heap as heap

    _, d, _ = leave_out
    calls = []
    monkeypatch.setattr(heap, "keep_freed", lambda *a: calls.append(a) or True)
    a = d.renderer().render(0.5, 1.5)
    assert len(calls) == 1
    b = d.renderer(keep_freed=False).render(0.5, 1.5)
    assert len(calls) == 1 and np.array_equal(a, b)


def test_a_grid_whose_every_view_is_coded_alone_renders_through_its_shared_map(leave_out):
    """A grid file whose every view is a JPEG 2000 image (the encoder's choice at high rates on
    views that predict each other badly) keeps its maps, the shared one in every cell. The
    renderer takes that map as the geometry; it used to look for the nearest view predicted
    through a map, found none, and raised. Captured positions are still the decoded views."""
    from formats.codec_api import Encoded
    from rlfc.txencode import TxEncoder
    from rlfc.txparams import TxParams

    full, _, _ = leave_out
    lf = make_lf(np.ascontiguousarray(full[::2, ::2]))
    enc = TxEncoder(lf, TxParams(), None, 10.0)
    res = enc.run_j2k(np.full(enc.n0, 44.0), 4.0)
    d, _ = open_encoded(lf, Encoded(*enc.pack(res)))
    lay = d.core.lay
    assert (lay.cell < 0).all() and lay.n_maps > 0 and sorted(d.core.img_of) == list(range(enc.n0))
    ren = d.renderer()
    shared = d.core.cell_map(0) / 16.0                # (its blocks of the frame: 5 of 6 rows here)
    got = ren._block_map(0.5, 0.5)
    assert (got == shared[:got.shape[0], :got.shape[1]]).all() and np.abs(shared).max() > 0
    assert (ren.render(1, 2) == d.decode_view(1, 2)).all()
    img = ren.render(0.5, 1.5)                        # (32.0 dB; without the map's parallax, 18.0)
    assert img.shape == full.shape[2:] and psnr_rgb(full[1, 3], img) > 28
    assert psnr_rgb(full[1, 3], img) > psnr_rgb(full[1, 3], ren.render(0.5, 1.5, 0.0)) + 6
    with pytest.raises(ValueError):
        d.core.cell_map(lay.n_maps)


def test_refocus_quilt_and_bad_cameras(leave_out):
    _, d, _ = leave_out
    ren = d.renderer()
    sharp = ren.render(1, 1, focus=4.0, aperture=1.5)        # focused at the scene's disparity
    blurred = ren.render(1, 1, focus=-4.0, aperture=1.5)
    ref = d.decode_view(1, 1).astype(float)
    assert psnr_rgb(ref, sharp) > psnr_rgb(ref, blurred) + 3
    q = ren.quilt(3, 2)
    assert q.shape == (2 * d.height, 3 * d.width, 3)
    for bad in ((5.0, 0.0), (0.0, -2.0), (float("nan"), 1.0)):
        with pytest.raises(ParameterError):
            ren.render(*bad)
    # a focus past the views' size leaves every sample off its image (1e300 overflowed into a
    # ValueError, 1e30 drew edge pixels); at the limit it still renders
    lim = max(d.height, d.width)
    for focus in (1e300, -1e30, lim + 0.5):
        with pytest.raises(ParameterError, match="focus"):
            ren.render(1, 1, focus=focus, aperture=1.0)
    assert ren.render(1, 1, focus=-lim, aperture=1.0).shape == (d.height, d.width, 3)
    # values that are not numbers say so (a string focus was numpy's TypeError; a string
    # position "outside the grid")
    for args, why in (((1, 1, "x"), "must be numbers"), ((1, 1, None, "1"), "must be numbers"),
                      (("1", 1), "camera s must be a number"), ((1, True), "camera t must be a number")):
        with pytest.raises(ParameterError, match=why):
            ren.render(*args)


def test_render_cli(leave_out, tmp_path, capsys):
    from formats.imageio import read_image

    _, d, blob = leave_out
    f = tmp_path / "g.lfc"
    f.write_bytes(blob)
    assert main(["render", str(f), str(tmp_path / "v.png"), "--at", "0.5,1.5", "--quiet"]) == 0
    assert (read_image(tmp_path / "v.png") == d.renderer().render(0.5, 1.5)).all()
    assert main(["render", str(f), str(tmp_path / "q.png"), "--quilt", "4x2", "--quiet"]) == 0
    assert read_image(tmp_path / "q.png").shape == (2 * d.height, 4 * d.width, 3)
    assert main(["render", str(f), str(tmp_path / "v.png"), "--at", "9,9", "--quiet"]) == 2
    assert main(["render", str(f), str(tmp_path / "v.png"), "--at", "1", "--quiet"]) == 2
    assert main(["render", str(f), str(tmp_path / "v.jpg"), "--quiet"]) == 2
    assert "outside the grid" in capsys.readouterr().err


@pytest.mark.parametrize("robust", [True, False])
def test_torch_renderer_agrees_with_numpy(leave_out, robust):
    """The torch path (here on the CPU; the same code runs on a GPU) gives the numpy frames within
    float rounding: planes within 1e-3, pixels within one rounding step per plane."""
    _, d, _ = leave_out
    a = d.renderer(robust=robust)
    b = d.renderer(robust=robust, device="cpu")
    assert b.ops.name == "torch" and a.ops.name == "numpy"
    for cam in ((0.5, 0.5), (0.25, 1.7), (1.9, 0.1), (-0.4, 2.3), (1.0, 1.0)):
        pa, pb = a.render_planes(*cam), b.render_planes(*cam).numpy()
        assert pa.shape == pb.shape and np.abs(pa - pb).max() < 1e-3, cam
        assert np.abs(a.render(*cam).astype(int) - b.render(*cam)).max() <= 3      # ±1 per plane, mixed
    assert a.blocks_decoded == b.blocks_decoded and a.blocks_requested == b.blocks_requested
    pa = a.render_planes(1, 1, focus=3.0, aperture=1.5)
    assert np.abs(pa - b.render_planes(1, 1, focus=3.0, aperture=1.5).numpy()).max() < 1e-3


@pytest.mark.parametrize("P", [1, 2, 3, 4])
@pytest.mark.parametrize("cubic", [False, True])
def test_numpy_samples_at_the_exact_positions_for_every_plane_count(P, cubic):
    """The numpy sampler (OpenCV's remap) weighs the taps at the exact float position for 1–4
    planes, as the torch sampler does: OpenCV 5.0 rounds a two-channel bilinear remap's
    positions to 1/32 pixel (0.50625 → 0.5), which made grey+alpha files' robust choice differ
    from torch's and the viewer's (16-bit: up to 1 243 levels on the golden file)."""
    from rlfc.render_ops import make_ops

    rng = np.random.default_rng(P)
    buf = rng.uniform(0, 1000, (12, 20, P)).astype(np.float32)
    Y = rng.uniform(1, 9, (3, 11)).astype(np.float32)
    X = rng.uniform(1, 17, (3, 11)).astype(np.float32)
    Y[0, 0] = 4.50625                               # (0.2/32 past a 1/32 step)
    import torch

    a = make_ops("numpy").remap(buf, X, Y, cubic)
    b = make_ops("cpu").remap_many([torch.from_numpy(buf)], torch.from_numpy(X[None]), torch.from_numpy(Y[None]), cubic)[0].numpy()
    assert a.shape == b.shape == (3, 11, P) and np.abs(a - b).max() < 0.02


def test_torch_renderer_agrees_with_numpy_on_16_bit_grey_and_alpha():
    """The golden 16-bit grey+alpha file (29×37 views: the padding's blocks past the frame are
    not the frame's, for the robust choice's median either): torch and numpy frames within float
    rounding (float32 sums of 16-bit values: below half a level), robust and not."""
    from formats import open_decoder, open_lfc

    d = open_decoder(open_lfc(Path(__file__).parents[1] / "data" / "golden" / "rlfc_tx2_lossless_ga16.lfc"))
    for robust in (True, False):
        a, b = d.renderer(robust=robust), d.renderer(robust=robust, device="cpu")
        for cam in ((0.9, 1.8), (1.05, 1.68), (1.65, 1.2), (3.0, 1.5), (2.3, 0.4)):
            pa, pb = a.render_planes(*cam), b.render_planes(*cam).numpy()
            assert np.abs(pa - pb).max() < 0.5, (robust, cam)          # (of 65 535)


def test_render_device_choice_and_errors(leave_out, tmp_path, capsys):
    from formats.imageio import read_image

    _, d, blob = leave_out
    assert d.renderer(device="numpy").ops.name == "numpy"
    assert d.renderer(device="auto").ops.name in ("numpy", "torch")
    for bad in ("abc", "", "cuda:99" if __import__("torch").cuda.is_available() else "cuda", 3):
        with pytest.raises(ParameterError):
            d.renderer(device=bad)
    f = tmp_path / "g.lfc"
    f.write_bytes(blob)
    assert main(["render", str(f), str(tmp_path / "n.png"), "--at", "0.5,1.5", "--device", "numpy", "--quiet"]) == 0
    assert main(["render", str(f), str(tmp_path / "t.png"), "--at", "0.5,1.5", "--device", "cpu", "--quiet"]) == 0
    n, t = read_image(tmp_path / "n.png").astype(int), read_image(tmp_path / "t.png")
    assert np.abs(n - t).max() <= 3
    assert main(["render", str(f), str(tmp_path / "x.png"), "--device", "abc", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "device 'abc' is not usable here (not a torch device type); a torch device is cpu, cuda or cuda:N" in err
    assert len(err.splitlines()) == 1


@pytest.mark.parametrize("device", [None, "cpu"])
def test_blocks_touched_cover_the_bicubic_taps(leave_out, device):
    """The blocks decoded for a set of positions cover every tap the sampling reads: bilinear
    floor … floor + 1, bicubic floor − 1 … floor + 2 (a whole frame touches nearly every block of
    its sources, so this is checked on the positions directly)."""
    _, d, _ = leave_out
    B = d.block_size
    ren = d.renderer(device=device)
    yy, xx = ren.ops.grid(d.height, d.width)
    Y, X = yy * 0 + (B + 0.3), xx * 0 + (B + 0.5)     # every position just past block row/col 1's start
    lin, cub = ren._blocks_touched(Y, X), ren._blocks_touched(Y, X, cubic=True)
    assert np.argwhere(lin).tolist() == [[1, 1]]
    assert np.argwhere(cub).tolist() == [[0, 0], [0, 1], [1, 0], [1, 1]]
    img = ren._sample(0, Y, X, cubic=True)               # a cold cache: only those blocks decoded
    assert ren.blocks_decoded == 4 and np.isfinite(ren.ops.to_numpy(img)).all()
    ref = d.renderer(device=device)
    ref._sample(0, *ref.ops.grid(d.height, d.width))     # every block of view 0 decoded
    assert (ren.ops.to_numpy(ref._sample(0, Y, X, cubic=True)) == ren.ops.to_numpy(img)).all()


def test_blocks_needed_are_the_union_of_each_tiles_rectangle(leave_out):
    """The vectorized bookkeeping (a difference array over all planes of a call) marks exactly
    the blocks of every tile's rectangle [floor(lo) − m, floor(hi) + m'] // B, clipped."""
    _, d, _ = leave_out
    ren = d.renderer()
    rng = np.random.default_rng(3)
    B = d.block_size
    for cubic in (False, True):
        lo_m, hi_m = (1, 2) if cubic else (0, 1)
        n, ty, tx = 3, 5, 6
        ylo = rng.uniform(0, d.height - 1, (n, ty, tx)).astype(np.float32)
        xlo = rng.uniform(0, d.width - 1, (n, ty, tx)).astype(np.float32)
        yhi = np.minimum(ylo + rng.exponential(6, ylo.shape), d.height - 1).astype(np.float32)
        xhi = np.minimum(xlo + rng.exponential(6, xlo.shape), d.width - 1).astype(np.float32)
        got = ren._need_many(ylo, yhi, xlo, xhi, cubic)
        want = np.zeros((n, d.nby, d.nbx), bool)
        for k, i, j in np.ndindex(n, ty, tx):
            y0 = max(int(np.floor(ylo[k, i, j])) - lo_m, 0) // B
            y1 = min(int(np.floor(yhi[k, i, j])) + hi_m, d.height - 1) // B
            x0 = max(int(np.floor(xlo[k, i, j])) - lo_m, 0) // B
            x1 = min(int(np.floor(xhi[k, i, j])) + hi_m, d.width - 1) // B
            want[k, y0:y1 + 1, x0:x1 + 1] = True
        assert (got == want).all()


def test_robust_choice_keeps_the_smoother_candidate_at_exact_agreement_on_every_backend():
    """Where the sources agree exactly, every candidate's disagreement is 0 up to the rounding
    residue a backend leaves (numpy/OpenCV: -1.1e-16 after a box mean; torch: 0). That residue
    chose the more detailed candidate on numpy and not on torch (stanford_chess at 40 dB: up to
    1.7 levels of chroma on 19-206 pixels in 4 of 12 frames of the benchmark's path). Both now
    keep the smoothest candidate at such ties, and at disagreements exactly at the margin (half
    of the best: stanford_chess again, where float32 rounding put torch below it and numpy not),
    and still take a real improvement."""
    import torch

    from rlfc.render import robust_choice
    from rlfc.render_ops import make_ops

    exact = [np.array([[0.0, 0.0, 8.0, 8.0, 0.09027775]]), np.array([[0.0, 0.0, 3.0, 5.0, 0.045138875]]),
             np.array([[0.0, 0.0, 2.0, 1.0, 0.045138875]])]
    residue = [exact[0], exact[1] - np.array([[1.1e-16, 1.1e-16, 0, 0, 3.7e-9]]),
               exact[2] + np.array([[-1.1e-16, 4.4e-16, 0, 0, -3.7e-9]])]
    want = [[0, 0, 1, 2, 0]]                     # ties keep 0; 3 < 4 wins, then 1 < 2.5 wins;
    #                                              exactly half the disagreement is a tie at the margin
    for ops, costs in ((make_ops("numpy"), residue), (make_ops("cpu"), [torch.from_numpy(c) for c in exact]),
                       (make_ops("cpu"), [torch.from_numpy(c) for c in residue])):
        got = robust_choice(ops, costs)
        assert np.array_equal(np.asarray(got), want), (ops.name, got)


def test_a_camera_on_a_row_of_views_within_rounding_uses_that_row_only(leave_out):
    """cs + r·sin(π) is 1.2e-16 off the row: its sources of weight ~1e-16 add nothing a float32
    frame holds but cost their blocks and samples; the frame is the same."""
    _, d, _ = leave_out
    ren = d.renderer()
    src = ren._sources(1.0 + 2.2e-16, 0.5, 0.0)
    assert sorted((r, c) for r, c, _ in src) == [(1, 0), (1, 1)] and sum(w for *_, w in src) == 1.0
    assert len(ren._sources(1.0 - 1e-10, 0.5 + 1e-10, 0.0)) == 2
    assert (ren.render(1.0 + 2.2e-16, 0.5) == ren.render(1.0, 0.5)).all()


@pytest.mark.parametrize("device", [None, "cpu"])
def test_blocks_named_from_the_maps_cover_every_tap(leave_out, device):
    """The blocks a frame decodes are named on the host from the block maps (the candidates'
    range, no pass over the position planes and no device round trip): with scrambled maps
    (−6…+6 px per view step, per block), frames rendered from a cold cache equal frames from a
    cache holding every block, robust, fast, refocused and synthetic-aperture alike; for one
    disparity plane the blocks named are exactly those the positions touch."""
    _, d, _ = leave_out
    rng = np.random.default_rng(5)
    cold, full = d.renderer(device=device), d.renderer(device=device)
    core = d.core
    disp = rng.integers(-96, 97, (core.lay.n_maps, core.nby8, core.nbx8)) / 16.0
    for ren in (cold, full):
        ren._maps = (lambda v: disp[core.lay.cell[v]], *ren._maps[1:])
    yy, xx = full.ops.grid(d.height, d.width)
    for v in range(d.rows * d.cols):
        full._sample(v, yy, xx, cubic=True)
    assert full.blocks_decoded == d.rows * d.cols * d.nby * d.nbx
    fast = d.renderer(device=device, robust=False)
    fast._maps = cold._maps
    for ren in (cold, fast):                  # frames never measure positions on the device
        ren.ops.tile_ranges = lambda planes: pytest.fail("a frame measured its positions")
    for s, t, focus, ap in ((0.4, 0.7, None, 0.0), (1.3, 0.2, None, 0.0), (0.5, 1.5, None, 0.0),
                            (1.0, 1.0, 2.5, 1.2), (0.2, 1.9, -3.0, 0.0)):
        want = full.ops.to_numpy(full.render_planes(s, t, focus, ap))
        assert (cold.ops.to_numpy(cold.render_planes(s, t, focus, ap)) == want).all()
        full.robust = False
        assert (fast.ops.to_numpy(fast.render_planes(s, t, focus, ap))
                == full.ops.to_numpy(full.render_planes(s, t, focus, ap))).all()
        full.robust = True
    assert 0 < cold.blocks_decoded < full.blocks_decoded
    # per tile, the extents from the maps are exactly those of the clamped positions: of one
    # plane, and over the robust choice's three candidates their union (min of lows, max of highs)
    import cv2

    from rlfc.render_ops import NumpyOps

    npo = NumpyOps()
    blk = fast._block_map(0.4, 0.7).astype(np.float32)
    cands = [blk, cv2.medianBlur(blk, 5), np.full_like(blk, np.median(blk))]
    gy, gx = npo.grid(d.height, d.width)
    for r, c in ((0, 0), (0, 1), (1, 0), (1, 1)):
        a, b = 0.4 - r, 0.7 - c
        ext = []
        for m in cands:
            D = npo.from_blocks(m, d.height, d.width)
            lo, hi = npo.tile_ranges([npo.clamp(gy + D * float(a), d.height - 1),
                                      npo.clamp(gx + D * float(b), d.width - 1)])
            ext.append((lo[0], hi[0], lo[1], hi[1]))
            got = fast._tile_extents([(a, b)], m, m)
            assert all((g[0] == e).all() for g, e in zip(got, ext[-1]))
        got = fast._tile_extents([(a, b)], np.min(cands, 0), np.max(cands, 0))
        for i, f in enumerate((np.minimum, np.maximum, np.minimum, np.maximum)):
            assert (got[i][0] == f.reduce([e[i] for e in ext])).all()


@pytest.mark.parametrize("device", [None, "cpu"])
def test_the_robust_choice_is_made_per_cell(device):
    """Choosing the disparity on the grid of every ROBUST_STEP-th pixel and repeating it over
    each cell gives the per-pixel choice, because every candidate is constant over a cell (per
    8×8 block maps, or one value): checked on a frame that is not a multiple of 8."""
    from rlfc.render import ROBUST_STEP as S
    from rlfc.render_ops import TILE, NumpyOps, make_ops

    assert TILE % S == 0
    H, W = 37, 45
    rng = np.random.default_rng(2)
    npo, ops = NumpyOps(), make_ops(device)
    maps = [rng.normal(0, 3, (-(-H // 8), -(-W // 8))).astype(np.float32) for _ in range(2)]
    full = [npo.const(H, W, 1.25)] + [npo.from_blocks(m, H, W) for m in maps]
    sel = rng.integers(0, 3, (-(-H // S), -(-W // S)))
    want = np.choose(np.repeat(np.repeat(sel, S, 0), S, 1)[:H, :W], full)
    if device is None:
        got = ops.choose(sel, S, H, W, [npo.sub(c, S) for c in full])
    else:
        import torch

        got = ops.choose(torch.as_tensor(sel), S, H, W, [torch.as_tensor(npo.sub(c, S)) for c in full]).numpy()
    assert got.dtype == np.float32 and (got == want).all()


def test_the_frames_median_is_numpys():
    """The robust choice's median disparity (``median_f32``, which spares a first frame numpy.ma's
    import) is ``np.median``'s value: odd and even sizes, ties, tiny and large values, NaN."""
    import warnings

    from rlfc.render_ops import median_f32

    rng = np.random.default_rng(3)
    for n in list(range(1, 34)) + [4095, 4096]:
        for scale in (1.0, 1e-3, 1e4):
            a = (rng.standard_normal(n) * scale).astype(np.float32)
            for v in (a, np.round(a), a.reshape(1, -1)):
                want = np.median(v)
                got = median_f32(v)
                assert got.dtype == np.float32 and got == want, (n, scale, got, want)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert np.isnan(np.median(np.float32([1, np.nan, 2]))) and np.isnan(median_f32(np.float32([1, np.nan, 2])))


def test_the_robust_choice_ignores_each_source_brightness():
    """The disagreement the robust choice compares takes each source's luma less its own box mean
    (its brightness: a vignette or an exposure of its own, ``ROBUST_LEVEL_WINDOW``): sources that
    differ by an offset and a slow gain agree (a gain-only disagreement was ~10^3 here and made the
    smoothest candidate win on a vignetted grid), a shifted texture still disagrees; numpy and
    torch alike."""
    import torch

    from rlfc.render_ops import make_ops

    rng = np.random.default_rng(3)
    tex = rng.uniform(0, 200, (40, 48)).astype(np.float32)
    yy, xx = np.mgrid[:40, :48].astype(np.float32)
    slow = (40 + 0.2 * yy + 0.3 * xx).astype(np.float32)              # an offset changing slowly
    pairs = {"brightness": [tex, tex + slow], "shifted": [tex, np.roll(tex, 3, axis=1)]}
    for name, lum in pairs.items():
        got = []
        for dev in ("numpy", "cpu"):
            ops = make_ops(dev)
            x = lum if dev == "numpy" else torch.from_numpy(np.stack(lum))
            cost = ops.disagreement(x, [0.5, 0.5], 4, 16)[0]
            got.append(cost if dev == "numpy" else cost.numpy())
        inner = (slice(8, -8), slice(8, -8))                          # (the box's reflected edges apart)
        if name == "brightness":
            assert got[0][inner].max() < 0.5, got[0][inner].max()
        else:
            assert got[0][inner].min() > 100
        np.testing.assert_allclose(got[0], got[1], rtol=1e-4, atol=1e-2)
