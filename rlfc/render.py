"""Novel views from a compressed grid light field: disparity-compensated interpolation of the
captured views around a camera position, fetching only the blocks a frame needs.

A camera is a continuous position (row s, column t) on the grid's plane, in view units
(view (r, c) sits at (r, c)). Pixel (y, x) of the new view takes, from a captured view at
(r, c), the sample at (y + d·(s − r), x + d·(t − c)), d the scene's disparity at that pixel in
pixels per view step (the sign convention of the tx prediction: view v samples key k at
y + d·(pos_v − pos_k)), bicubically; the views are blended with weights that fall off with their
distance to (s, t) (bilinear between the 4 around it; a disc of radius ``aperture`` view steps
for synthetic-aperture refocusing, where d is the ``focus`` disparity everywhere).

Geometry: the ``tx`` profile's disparity maps (one per 8×8 block and cell of views, the ones its
prediction uses); other files, or ``focus=`` given, use one disparity for the whole frame. A file
with per-view warps (``tx`` version 5, :mod:`rlfc.txwarp`) moves each source's samples by its
warp less the camera's, the camera's being the sources' blend of theirs (so a captured view is
its own pixels, and a camera between views has their interpolated warp).
Blocks come from the batched random-access decoder through an LRU cache of decoded blocks.
The pixel work runs on numpy + OpenCV, or on torch (a GPU when present) with ``device=``;
:mod:`rlfc.render_ops` holds both.
"""
from __future__ import annotations

import collections

import numpy as np

from formats.campath import assemble_quilt, quilt_positions
from formats.codec_api import is_real
from formats.errors import ParameterError

from .render_ops import make_ops, median_f32


ROBUST_WINDOW = 17      # pixels: the box over which the sources' disagreement is averaged
ROBUST_LEVEL_WINDOW = 64   # pixels: the box whose mean (a source's local brightness) each source's luma
                           # loses before the disagreement (a vignette or exposure of its own is not a
                           # geometric disagreement: antinous_vignette +1.6 dB; BENCHMARKS.md, stop 94)
ROBUST_MARGIN = 0.5     # a more detailed disparity candidate must halve the disagreement to win
ROBUST_STEP = 4         # the choice is made on every 4th pixel (the frame is rendered once, at full size);
                        # it divides the maps' 8×8 blocks, so each candidate is constant over a choice's cell
ROBUST_TIE = 1e-4       # relative: a candidate must beat the margin by more than rounding (disagreements
                        # exactly at the margin, e.g. one of two differing samples gone, are ties)
SNAP = 1e-9             # views: a camera this close to a row/column of views is on it
ROBUST_FLOOR = 1e-6     # disagreements (luma variance, planes' units²) below this are 0: a box mean by
                        # running sums leaves ±1e-16 where the sources agree exactly, and a tie at zero
                        # must keep the smoother candidate on every backend (numpy/OpenCV and torch)


def _snap(f: float) -> float:
    """A fraction of a view step within SNAP of 0 or 1 is 0 or 1."""
    return 0.0 if f < SNAP else 1.0 if f > 1.0 - SNAP else f


def robust_choice(ops, costs):
    """Index of the chosen candidate per grid point from the candidates' disagreements
    (``costs``, smoothest candidate first, each (h, w) on ``ops``' arrays): a later candidate
    replaces the choice where its disagreement is below ROBUST_MARGIN times the best so far, by
    more than ROBUST_TIE (relative). Disagreements below ROBUST_FLOOR count as 0. Exact agreement,
    and disagreements exactly at the margin, are ties that keep the smoother candidate whatever
    rounding each backend leaves (numpy/OpenCV and torch round differently)."""
    best = choice = None
    for k, cost in enumerate(costs):
        cost = cost * (cost >= ROBUST_FLOOR)
        if best is None:
            best, choice = cost, ops.zeros_int(tuple(cost.shape))
        else:
            win = cost < best * (ROBUST_MARGIN * (1 - ROBUST_TIE))
            best = ops.where(win, cost, best)
            choice = ops.where(win, k, choice)          # (a masked store would sync a GPU)
    return choice


class Renderer:
    """Renders views at continuous grid positions from an :class:`rlfc.decoder.RlfcDecoder`.

    Args:
        decoder: an opened RLFC decoder of a grid light field.
        cache_mib: memory for decoded blocks, kept per view (the least recently used views go
            first; a frame's views are decoded whatever the budget).
        margin: how far outside the grid (in view steps) a camera may go (extrapolation).
        device: None (or "numpy") renders with numpy and OpenCV on the CPU; "auto" with torch on
            a CUDA GPU when one is present, else numpy; a torch device ("cuda", "cpu", …) renders
            with torch there (the blocks are still decoded by the CPU decoder and
            uploaded once each); both give the same planes within float rounding (about 1e-4),
            so pixels within one step of rounding per plane.
        robust: choose per pixel among smoother disparities where the file's maps make the
            sources disagree (about 3× the sampling work of ``robust=False``; see
            :meth:`_consistent`).
        keep_freed: ask the process's malloc to keep the blocks a frame frees for the next
            (:func:`formats.heap.keep_freed`, as ``lfcodec render`` does; glibc only): without
            it every frame maps its large temporaries afresh and faults their pages in again.
            It sets the whole process's malloc (blocks below 32 MiB from the heap, up to 64 MiB
            of freed memory kept at its top) and is left set; an environment's
            ``MALLOC_MMAP_THRESHOLD_`` / ``MALLOC_TRIM_THRESHOLD_`` wins. On the six dense grids
            at 40 dB: warm frames 1.3–1.6× as fast (the first frame of a fresh process within
            the box's noise; BENCHMARKS.md, stop 89). False leaves malloc as it is.

    Attributes:
        blocks_decoded, blocks_requested: counters over the renderer's life (hit rate =
            1 − decoded / requested).
    """

    def __init__(self, decoder, cache_mib: float = 256.0, margin: float = 0.5, robust: bool = True,
                 device: str | None = None, keep_freed: bool = True):
        self.d = decoder
        if isinstance(cache_mib, bool) or not isinstance(cache_mib, (int, float, np.integer, np.floating)) \
                or not 0 <= cache_mib < 1 << 40:
            raise ParameterError(f"cache_mib must be a number of MiB >= 0, got {cache_mib!r}")
        if isinstance(margin, bool) or not isinstance(margin, (int, float, np.integer, np.floating)) \
                or not 0 <= margin <= 1e6:
            raise ParameterError(f"margin must be a number of views >= 0, got {margin!r}")
        self.robust = bool(robust)
        self.ops = make_ops(device)
        if keep_freed:
            from formats.heap import keep_freed as keep

            keep()                                  # (frame after frame: freed blocks reused)
        scene = decoder.file.meta.get("scene", {}) if hasattr(decoder, "file") else {}
        if isinstance(scene, dict) and scene.get("layout") == "posed":
            raise ParameterError("novel views are rendered on grids of parallel cameras; this capture is posed "
                                 "(decode its views, or train an LFN)")
        self.cache: collections.OrderedDict = collections.OrderedDict()
        view_bytes = decoder.nby * decoder.nbx * decoder.block_size ** 2 * decoder.P * 4
        self.cache_views = int(cache_mib * (1 << 20) // view_bytes)
        self.margin = float(margin)
        self.blocks_decoded = 0
        self.blocks_requested = 0
        self._grid = None
        core = decoder.core
        # (map m → (ny8, nx8) float64 px per view step, positions, views with a map, each view's map):
        # each map read from the file when a frame first needs it
        self._maps = None
        if hasattr(core, "cell_map") and core.lay.n_maps:
            lay = core.lay
            self._maps = (lambda m: core.cell_map(m) / 16.0, lay.positions.astype(np.float64),
                          np.flatnonzero(lay.cell >= 0), lay.cell)
        # per-view warps of a tx version 5 file (rlfc.txwarp): (N0, 4) a, b, cx, cy, else None
        warp = getattr(getattr(core, "lay", None), "warp", None)
        self._warp = None if warp is None or not np.any(warp) else np.asarray(warp, np.float64)

    def _warp_coefs(self, src):
        """Per source (row, column, weight) of a warped file, where its pixel lies from where the
        camera's does (the camera's warp: the sources' blend of theirs, so that a captured view
        is its own pixels): (y coefficients, x coefficients), each (n, 3) (of y, of x, constant;
        px), and (n, 2) pads (y, x): the offsets' largest size over the frame, whole pixels plus
        one. None for files without warps."""
        if self._warp is None:
            return None
        d = self.d
        p = self._warp[[r * d.cols + c for r, c, _ in src]]                     # (n, 4)
        dp = p - np.asarray([w for _, _, w in src]) @ p
        a, b, cx, cy = (dp[:, i] for i in range(4))
        k = 1.0 / 65536
        cy_ = np.stack([a * k, b * k, cy / 256], 1)            # off_y = (b·x + a·y) / 2^16 + cy / 256
        cx_ = np.stack([-b * k, a * k, cx / 256], 1)           # off_x = (a·x − b·y) / 2^16 + cx / 256
        cor = np.array([[0, 0, 1], [0, d.width - 1, 1], [d.height - 1, 0, 1], [d.height - 1, d.width - 1, 1]], np.float64)
        pad = np.stack([np.abs(cy_ @ cor.T).max(1), np.abs(cx_ @ cor.T).max(1)], 1)
        return cy_, cx_, np.ceil(pad) + 1

    # -- geometry --------------------------------------------------------------------------
    def _block_map(self, s: float, t: float) -> np.ndarray | None:
        """(ceil(H/8), ceil(W/8)) float64 disparity per 8×8 block of the frame at camera (s, t):
        the map of the cell of the nearest view predicted from key views (where every view is
        coded alone, the file's first map, the shared one), without the blocks of the padding
        past the image (the robust choice's median and median filter see the frame's blocks, as
        the viewer's renderer does); None without maps."""
        if self._maps is None:
            return None
        map_of, pos, users, cell = self._maps
        if users.size == 0:               # every view coded alone: the first map (the shared one)
            m = map_of(0)
        else:
            near = users[np.argmin(np.hypot(pos[users, 0] - s, pos[users, 1] - t))]
            m = map_of(int(cell[near]))
        return m[:-(-self.d.height // 8), :-(-self.d.width // 8)]

    def disparity(self, s: float, t: float) -> np.ndarray | None:
        """(H, W) disparity in pixels per view step at camera (s, t): the map of the cell of the
        nearest view predicted from key views, upsampled per 8×8 block; None without maps."""
        m = self._block_map(s, t)
        if m is None:
            return None
        return np.repeat(np.repeat(m, 8, 0), 8, 1)[:self.d.height, :self.d.width]

    # -- blocks ----------------------------------------------------------------------------
    def _view_buffer(self, view: int):
        """(planes buffer (see :mod:`rlfc.render_ops`), filled (nby, nbx) bool) of a view,
        LRU-cached."""
        got = self.cache.get(view)
        if got is None:
            d = self.d
            B = d.block_size
            got = (self.ops.buffer(d.nby * B, d.nbx * B, d.P), np.zeros((d.nby, d.nbx), bool))
            self.cache[view] = got
            while len(self.cache) > max(1, self.cache_views):
                self.cache.popitem(last=False)
        else:
            self.cache.move_to_end(view)
        return got

    def _blocks_touched(self, Y, X, cubic: bool = False) -> np.ndarray:
        """(nby, nbx) bool: the blocks that the taps at clamped positions (Y, X) read (bilinear:
        floor and floor + 1; bicubic: floor − 1 … floor + 2), from the extent of each 8×8 tile
        of positions (a superset when a tile's positions spread over more than two blocks)."""
        lo, hi = self.ops.tile_ranges([Y, X])
        return self._need_many(lo[:1], hi[:1], lo[1:], hi[1:], cubic)[0]

    def _need_many(self, ylo, yhi, xlo, xhi, cubic: bool) -> np.ndarray:
        """(n, nby, nbx) bool from the tile ranges (n, ty, tx) of n position planes."""
        d = self.d
        B, H, W = d.block_size, d.height, d.width
        lo, hi = (1, 2) if cubic else (0, 1)
        y0 = np.maximum(np.floor(ylo).astype(np.int64) - lo, 0) // B
        y1 = np.minimum(np.floor(yhi).astype(np.int64) + hi, H - 1) // B + 1
        x0 = np.maximum(np.floor(xlo).astype(np.int64) - lo, 0) // B
        x1 = np.minimum(np.floor(xhi).astype(np.int64) + hi, W - 1) // B + 1
        # each tile needs the rectangle of blocks [y0, y1) × [x0, x1): mark the rectangles'
        # corners ±1 in a difference array, then its 2-D prefix sum is > 0 exactly on their union
        # (one unweighted count per corner: no concatenated index or sign array, whose fresh
        # pages cost more than the counting)
        n, n1, cell = ylo.shape[0], d.nbx + 1, (d.nby + 1) * (d.nbx + 1)
        y0 = y0 * n1 + (np.arange(n) * cell)[:, None, None]
        y1 = y1 * n1 + (np.arange(n) * cell)[:, None, None]
        diff = np.bincount((y0 + x0).ravel(), minlength=n * cell)
        diff += np.bincount((y1 + x1).ravel(), minlength=n * cell)
        diff -= np.bincount((y0 + x1).ravel(), minlength=n * cell)
        diff -= np.bincount((y1 + x0).ravel(), minlength=n * cell)
        return (diff.reshape(n, d.nby + 1, n1).cumsum(1).cumsum(2) > 0)[:, :d.nby, :d.nbx]

    def _tile_extents(self, offs, dlo, dhi, pad=None):
        """(ylo, yhi, xlo, xhi), each (n, ty, tx) float32: per 8×8 tile, the extent of the positions
        (y + d·a, x + d·b) over its pixels (y, x), every disparity d within [``dlo``, ``dhi``]
        and each of the n ``offs`` (a, b) = the camera minus a source view, in view steps.

        Computed on the host from the per-tile disparities (floats or (ny8, nx8) maps, e.g. the
        range of the robust choice's candidates; a map may cover more blocks than the frame), not
        from the position planes: no device round trip in the middle of a frame, and no pass over
        every pixel. The positions are evaluated as the renderer evaluates them, in float32
        (``yy + d · float(a)``: a float32 product, then a float32 sum; positions are monotone
        in y and in d·a), at each tile's first and last pixel row / column, then clamped to the
        image: the same extents as :meth:`rlfc.render_ops.NumpyOps.tile_ranges` of those
        planes, the union over the range (tested). ``pad`` (n, 2): pixels to widen each offset's
        extents by, rows and columns (per-view warps' offsets), before the clamp."""
        d = self.d
        H, W = d.height, d.width
        ny, nx = -(-H // 8), -(-W // 8)
        f32 = np.float32
        dlo, dhi = (np.broadcast_to(np.atleast_2d(np.asarray(m, f32))[:ny, :nx], (ny, nx)) for m in (dlo, dhi))
        y0 = (np.arange(ny, dtype=f32) * 8)[:, None]
        y1 = np.minimum(y0 + 7, f32(H - 1))
        x0 = (np.arange(nx, dtype=f32) * 8)[None, :]
        x1 = np.minimum(x0 + 7, f32(W - 1))
        ext = []
        for a, b in offs:
            ca = (dlo * f32(a), dhi * f32(a))
            cb = (dlo * f32(b), dhi * f32(b))
            ext.append((np.minimum(y0 + ca[0], y0 + ca[1]), np.maximum(y1 + ca[0], y1 + ca[1]),
                        np.minimum(x0 + cb[0], x0 + cb[1]), np.maximum(x1 + cb[0], x1 + cb[1])))
        st = [np.stack([e[i] for e in ext]) for i in range(4)]
        if pad is not None:
            py, px = (np.asarray(pad, f32)[:, j, None, None] for j in (0, 1))
            st = [st[0] - py, st[1] + py, st[2] - px, st[3] + px]
        ylo, yhi, xlo, xhi = (np.clip(x, 0, hi) for x, hi in zip(st, (H - 1, H - 1, W - 1, W - 1)))
        return ylo, yhi, xlo, xhi

    def _needs_from_maps(self, offs, dlo, dhi, cubic: bool, pad=None) -> np.ndarray:
        """(n, nby, nbx) bool: the blocks that the positions of :meth:`_tile_extents` touch."""
        return self._need_many(*self._tile_extents(offs, dlo, dhi, pad), cubic)

    def _sample(self, view: int, Y, X, cubic: bool = False):
        """Samples (H, W, P) float32 of one view's planes at pixel positions Y, X (float32,
        clamped to the image; bilinear, or bicubic): :meth:`_sample_many` of one view."""
        got = self._sample_many([view], [Y], [X], cubic)
        return got[0]

    def _sample_many(self, views, Ys, Xs, cubic: bool = False, needs=None):
        """Samples of several views at their pixel positions (float32 planes, clamped here to
        the image): a list of (H, W, P) (numpy) or an (S, H, W, P) tensor (torch). The blocks the
        taps touch that are not decoded yet are decoded in one batched call for all the views;
        sampling is OpenCV's remap, or :class:`rlfc.render_ops.TorchOps` (all views at once).
        ``needs`` (len(views), nby, nbx) bool, when given, are the blocks to have decoded (a
        superset of those the taps touch, e.g. from :meth:`_needs_from_maps`); else they are
        measured on the positions."""
        d = self.d
        B, ops = d.block_size, self.ops
        Ys = ops.clamp_all(Ys, d.height - 1)
        Xs = ops.clamp_all(Xs, d.width - 1)
        if needs is None:
            lo, hi = ops.tile_ranges(list(Ys) + list(Xs))
            n = len(views)
            needs = self._need_many(lo[:n], hi[:n], lo[n:], hi[n:], cubic)
            self.blocks_requested += int(needs.sum())
        bufs, union = [], {}
        for v, need in zip(views, needs):              # a view may come several times (candidates)
            img, filled = self._view_buffer(v)
            bufs.append(img)
            union[v] = (img, filled, need | union[v][2]) if v in union else (img, filled, need)
        want = [(v, img, filled, *np.nonzero(need & ~filled)) for v, (img, filled, need) in union.items()
                if (need & ~filled).any()]
        if want:
            vv = np.concatenate([np.full(w[3].size, w[0]) for w in want])
            got = d.decode_blocks(vv, np.concatenate([w[3] for w in want]), np.concatenate([w[4] for w in want]),
                                  planes=True)
            k = 0
            for v, img, filled, by, bx in want:
                ops.put_blocks(img, by, bx, got[k:k + by.size], B)
                filled[by, bx] = True
                k += by.size
                self.blocks_decoded += int(by.size)
        return ops.remap_many(bufs, Xs, Ys, cubic)

    # -- frames ----------------------------------------------------------------------------
    def _sources(self, s: float, t: float, aperture: float) -> list[tuple[int, int, float]]:
        R, C = self.d.rows, self.d.cols
        if aperture > 0:
            rr, cc = np.mgrid[0:R, 0:C]
            dist = np.hypot(rr - s, cc - t)
            sel = np.flatnonzero(dist.ravel() <= aperture)
            if sel.size == 0:
                sel = np.array([int(np.argmin(dist))])
            w = np.maximum(1.0 - dist.ravel()[sel] / (aperture + 1.0), 1e-3)
            return [(int(i) // C, int(i) % C, float(x)) for i, x in zip(sel, w / w.sum())]
        r0, c0 = int(np.clip(np.floor(s), 0, R - 1)), int(np.clip(np.floor(t), 0, C - 1))
        r1, c1 = min(r0 + 1, R - 1), min(c0 + 1, C - 1)
        # a camera within SNAP views of a row or column of views is on it: sources of weight ~1e-16
        # (cs + r·sin(π)) add nothing a float32 frame can hold, but cost their blocks and samples
        fs = _snap(float(np.clip(s - r0, 0, 1))) if r1 > r0 else 0.0
        ft = _snap(float(np.clip(t - c0, 0, 1))) if c1 > c0 else 0.0
        out = {}
        for r, c, w in ((r0, c0, (1 - fs) * (1 - ft)), (r0, c1, (1 - fs) * ft), (r1, c0, fs * (1 - ft)), (r1, c1, fs * ft)):
            if w > 0:
                out[(r, c)] = out.get((r, c), 0.0) + w
        return [(r, c, w) for (r, c), w in out.items()]

    def check_camera(self, s: float, t: float) -> None:
        """ParameterError unless (s, t) is a finite position within the grid ± ``margin``."""
        d = self.d
        for name, v, n in (("s", s, d.rows), ("t", t, d.cols)):
            if not is_real(v):
                raise ParameterError(f"camera {name} must be a number, got {v!r}")
            if not np.isfinite(v) or not -self.margin <= v <= n - 1 + self.margin:
                raise ParameterError(f"camera {name}={v!r} is outside the grid (0..{n - 1} ± {self.margin:g} views)")

    def render_path(self, cameras):
        """Frames along a camera path: ``cameras`` (N, 4) rows of (s, t, focus or NaN for the
        file's maps, aperture), e.g. from :func:`formats.campath.read_path`; yields (H, W, C)
        frames (every camera is checked first)."""
        cams = np.asarray(cameras, dtype=np.float64).reshape(-1, 4)
        for s, t, focus, ap in cams.tolist():
            self.check_camera(s, t)
            self.check_optics(None if np.isnan(focus) else focus, ap)
        for s, t, focus, ap in cams.tolist():
            yield self.render(s, t, None if np.isnan(focus) else focus, ap)

    def check_optics(self, focus: float | None, aperture: float) -> None:
        """A ParameterError unless aperture >= 0 and focus (None: the file's maps) is finite and
        within ± the views' larger side (further, every neighbour's samples leave its image)."""
        if not is_real(aperture) or (focus is not None and not is_real(focus)):
            raise ParameterError(f"focus (or None) and aperture must be numbers, got {focus!r} and {aperture!r}")
        if aperture < 0 or not np.isfinite(aperture) or (focus is not None and not np.isfinite(focus)):
            raise ParameterError(f"aperture must be >= 0 and focus finite, got focus {focus!r}, aperture {aperture!r}")
        lim = max(self.d.height, self.d.width)
        if focus is not None and abs(focus) > lim:
            raise ParameterError(f"focus {focus:g} is outside ±{lim} px per view step (the views' size)")

    def render(self, s: float, t: float, focus: float | None = None, aperture: float = 0.0) -> np.ndarray:
        """The view at grid position (s, t): (H, W, C) pixels of the file's dtype.

        Args:
            s, t: row and column position in view units (0 … rows−1, 0 … cols−1, ± margin).
            focus: disparity in pixels per view step to use everywhere (refocusing; default: the
                file's disparity maps, or 0 when it has none), within ± the views' larger side.
            aperture: synthetic-aperture radius in view steps (0 = a pinhole view).
        """
        return self.ops.to_pixels(self.render_planes(s, t, focus, aperture), self.d.dtype)

    def render_planes(self, s: float, t: float, focus: float | None = None, aperture: float = 0.0):
        """The view at (s, t) before rounding: (H, W, P) float32 planes of the file's colour
        transform (YCoCg-R [+ alpha] or grey [+ alpha]), a numpy array or, with ``device=``, a
        torch tensor on that device; arguments as :meth:`render`."""
        d = self.d
        ops = self.ops
        self.check_camera(s, t)
        self.check_optics(focus, aperture)
        blk = self._block_map(s, t) if focus is None and aperture == 0 else None
        src = self._sources(s, t, aperture)
        robust = blk is not None and len(src) > 1 and self.robust
        if blk is None:
            dlo = dhi = np.float32(focus or 0.0)
            disp = ops.const(d.height, d.width, float(dlo))
        else:                                       # host maps go to the device together, first
            import cv2

            blk = blk.astype(np.float32)
            cands = [blk] + ([cv2.medianBlur(blk, 5)] if robust else [])
            maps = ops.from_blocks_many(cands, d.height, d.width)
            disp = maps[0]
            if robust:                              # the frame's median disparity: the third candidate
                cands.append(np.full_like(blk, median_f32(blk)))
            dlo, dhi = np.min(cands, axis=0), np.max(cands, axis=0)
        # the blocks of every candidate disparity, from the host's maps: one decode call per
        # frame and no device round trip before the frame's last copy
        warp = self._warp_coefs(src)
        needs = self._needs_from_maps([(s - r, t - c) for r, c, _ in src], dlo, dhi, cubic=True,
                                      pad=None if warp is None else warp[2])
        self.blocks_requested += int(needs.sum())
        if self._grid is None:
            self._grid = ops.grid(d.height, d.width)
        if robust:
            disp = self._consistent(s, t, src, blk, disp, maps[1], needs, warp)
        return self._blend(s, t, src, disp, needs, warp)

    def _blend(self, s, t, src, disp, needs=None, warp=None):
        """(H, W, P) float32: the sources (view row, column, weight) warped to camera (s, t)
        by ``disp`` (H, W) pixels per view step (bicubic: bilinear sampling blurs what it shifts,
        0.05 to 1.4 dB lower in the leave-views-out benchmark), weighted and summed; ``warp``:
        :meth:`_warp_coefs` of the sources (their positions moved by their warps)."""
        d = self.d
        yy, xx = self._grid
        acc = None
        n = max(1, min(8, (1 << 21) // (d.height * d.width)))   # sources sampled together (bounds memory)
        for i in range(0, len(src), n):
            part = src[i:i + n]
            Ys = self.ops.shifted(yy, [disp], [s - r for r, c, _ in part])
            Xs = self.ops.shifted(xx, [disp], [t - c for r, c, _ in part])
            if warp is not None:
                Ys = self.ops.plus_affine(Ys, yy, xx, warp[0][i:i + n])
                Xs = self.ops.plus_affine(Xs, yy, xx, warp[1][i:i + n])
            smp = self._sample_many([r * d.cols + c for r, c, _ in part], Ys, Xs, cubic=True,
                                    needs=None if needs is None else needs[i:i + n])
            acc = self.ops.wsum(smp, [w for _, _, w in part], acc)
        return acc

    def _consistent(self, s, t, src, blk, disp, med, needs=None, warp=None):
        """(H, W) disparities: per pixel the most photo-consistent of three candidates,
        smoothest first: the frame's median disparity, the map's median over 5×5 blocks (``med``
        per pixel), the file's map (``blk`` per 8×8 block, ``disp`` per pixel). The choice is made on a grid of
        every ROBUST_STEP-th pixel: disagreement = the weighted variance of the sources' luma
        (each less its own mean over ROBUST_LEVEL_WINDOW² pixels) around their blend there,
        averaged over ROBUST_WINDOW² pixels; a later candidate replaces
        an earlier one where it has less than ROBUST_MARGIN times its disagreement (the maps are
        chosen for prediction bits, so on noisy captures some blocks carry disparities that fit
        the noise). The caller renders the frame once with them. ``needs`` (len(src), nby, nbx):
        the blocks the sources' samples touch (every candidate), measured on the positions when
        None; ``warp``: as :meth:`_blend`."""
        d, ops = self.d, self.ops
        yy, xx = self._grid
        H, W = d.height, d.width
        S = ROBUST_STEP
        ys, xs = ops.sub(yy, S), ops.sub(xx, S)
        # the candidates on the choice's grid (only there are they sampled and chosen)
        subs = [ops.const(*ys.shape, float(median_f32(blk))), ops.sub(med, S), ops.sub(disp, S)]
        Ys = ops.shifted(ys, subs, [s - r for r, _, _ in src])
        Xs = ops.shifted(xs, subs, [t - c for _, c, _ in src])
        if warp is not None:
            Ys = ops.plus_affine(Ys, ys, xs, warp[0], len(subs))
            Xs = ops.plus_affine(Xs, ys, xs, warp[1], len(subs))
        allsmp = ops.plane(self._sample_many([r * d.cols + c for _ in subs for r, c, _ in src], Ys, Xs,
                                             needs=None if needs is None else np.concatenate([needs] * len(subs))), 0)
        # (the brightness box at most 2·min(h, w) − 1 wide on the choice's grid: its reflected
        # edges then the same on every backend, OpenCV's and torch's)
        kb = max(1, min(ROBUST_LEVEL_WINDOW // S, 2 * min(ys.shape[-2:]) - 1))
        costs = ops.disagreement(allsmp, [w for _, _, w in src], max(1, ROBUST_WINDOW // S), kb)
        return ops.choose(robust_choice(ops, costs), S, H, W, subs)      # (candidates constant per cell)

    def quilt(self, cols: int, rows: int, focus: float | None = None) -> np.ndarray:
        """A quilt for light-field displays: ``rows`` × ``cols`` views along the grid's middle row
        from left to right (bottom-left first, as Looking Glass quilts are laid out), as one
        (rows·H, cols·W, C) image."""
        d = self.d
        return assemble_quilt([self.render(float(s), float(t), focus) for s, t in quilt_positions(d.rows, d.cols, cols, rows)],
                              cols, rows)
