"""Per-pixel network sizes (:class:`Foveated`, a part of :class:`lfn_stream.render.LfnRenderer`):
rays rendered each at its own size in a few grouped passes, foveation maps around a gaze point
with dithered transitions, and the mip render (sparser lattices at the coarser sizes, blended),
on the captured views' cameras or at a free pose."""
from __future__ import annotations

import math

import cv2
import numpy as np
import torch

from formats.codec_api import check_numbers
from formats.errors import FormatError, ParameterError

from .rays import camera_rays, view_rays

MAX_SIZE_PASSES = 16  # an all-integer size map with at most this many sizes runs one fused pass per size
MIP_LEVELS = 3        # render_lod_mip's coarsest lattice: every 2^3 pixels (the base network's 1/8 scale)
#: render_lod_mip's calibration (measured on three networks, BENCHMARKS.md): level j's lattice
#: (every 2^j pixels) runs the size made for 2^-(j − MIP_SHARPEN) of the full scale, and a pixel
#: at level m reads the lattices around m + MIP_OFFSET. The nested networks are smoother than
#: their nominal scale (a size sampled on such a lattice and upsampled is 33-65 dB from the same
#: size at every pixel, against 17-26 dB from the captured views), so a finer size on a sparser
#: lattice is as close to the captured views and faster; the offset is small enough that the
#: fovea (m = 0) stays on the full-density lattice alone
MIP_SHARPEN = 1.0
MIP_OFFSET = 0.25
MIP_BLEND = 0.25      # render_lod_mip: the part of each interval between two levels that blends them


def dither_threshold(height: int, width: int, frame: int = 0) -> np.ndarray:
    """(height, width) thresholds in [0, 1): interleaved gradient noise (Jimenez 2014), a
    closed-form low-discrepancy pattern with no low-frequency structure, shifted per ``frame``
    so that over a few frames every pixel takes each of its two sizes in proportion (temporal
    dither). float64, the same formula as the browser viewer could use."""
    y, x = np.mgrid[0:height, 0:width].astype(np.float64)
    shift = 5.588238 * (int(frame) % 64)
    return np.modf(52.9829189 * np.modf(0.06711056 * (x + shift) + 0.00583715 * (y + shift))[0])[0]


def size_levels(lo: float, hi: float, count: int) -> np.ndarray:
    """``count`` integer network sizes evenly spaced over [lo, hi] (rounded, distinct; float64):
    the sizes a dithered foveation map uses."""
    return np.unique(np.round(np.linspace(np.ceil(lo), np.floor(hi), count)))


def dither_sizes(lod: np.ndarray, sizes: np.ndarray, threshold: np.ndarray) -> np.ndarray:
    """Snap fractional sizes ``lod`` to the sorted integer ``sizes`` (K,): a value between
    sizes[j] and sizes[j+1] takes sizes[j+1] where its position between them exceeds
    ``threshold`` (same shape as lod, values in [0, 1)), else sizes[j]; values outside the
    range clip to its ends. The mean over thresholds is the fractional map (in neurons)."""
    s = np.asarray(sizes, np.float64)
    lod = np.clip(np.asarray(lod, np.float64), s[0], s[-1])
    if s.size == 1:
        return np.full_like(lod, s[0])
    j = np.clip(np.searchsorted(s, lod, side="right") - 1, 0, s.size - 2)
    a, b = s[j], s[j + 1]
    return np.where((lod - a) / (b - a) > threshold, b, a)


def plan_passes(top: np.ndarray, passes: int) -> list[tuple[int, int]]:
    """Group integer pass widths ``top`` (N,) into at most ``passes`` contiguous ranges [a, b]
    of least total cost Σ rays·b² (a pass runs at its largest width), by dynamic programming
    over the distinct widths. Returns the ranges in increasing order."""
    u, c = np.unique(np.asarray(top, np.int64), return_counts=True)
    k = u.size
    if k == 0:
        return []
    p = max(1, min(int(passes), k))
    cum = np.concatenate([[0], np.cumsum(c)]).astype(np.float64)
    cost = (cum[None, 1:] - cum[:-1, None]) * (u.astype(np.float64) ** 2)[None, :]     # [a, b]: rays a..b at u[b]
    cost[np.tril_indices(k, -1)] = np.inf
    best = cost[0].copy()                              # best[b]: ranges 0..b in one pass
    back = [np.zeros(k, np.int64)]
    for _ in range(1, p):
        # a new last range a..b after the best split of 0..a-1
        cand = np.concatenate([[np.inf], best[:-1]])[:, None] + cost              # (a, b)
        arg = np.argmin(cand, axis=0)
        nb = cand[arg, np.arange(k)]
        better = nb < best
        back.append(np.where(better, arg, -1))
        best = np.where(better, nb, best)
    ranges, b = [], k - 1
    for layer in range(len(back) - 1, 0, -1):         # follow the splits back
        a = int(back[layer][b])
        if a <= 0:
            continue
        ranges.append((int(u[a]), int(u[b])))
        b = a - 1
    ranges.append((int(u[0]), int(u[b])))
    return ranges[::-1]


class Foveated:
    """A renderer's per-pixel sizes."""

    @torch.no_grad()
    def render_rays_lod(self, rays: np.ndarray, neurons: np.ndarray, passes: int | None = None,
                        use_occupancy: bool = True) -> np.ndarray:
        """(N, 6) Plücker rays, each at its own fractional network size ``neurons`` (N,) → (N, 4)
        RGBA (premultiplied). Rays are grouped into at most ``passes`` network passes by size
        (:func:`plan_passes`: the grouping of least cost, a pass of n neurons costing ~ rays·n²);
        within a pass every ray keeps its exact size (:meth:`NestedLFN.forward_lod`), so the
        result does not depend on the grouping beyond float rounding and has no level steps.
        ``passes=None``: one pass per size when every size is an integer and there are at most
        16 of them (each pass then runs the fused integer-size network, as a dithered map
        from :meth:`foveation_map` needs), else 4."""
        lo, hi = self.neuron_range
        lod = np.asarray(neurons, np.float64).reshape(-1)
        if lod.shape[0] != rays.shape[0] or not np.isfinite(lod).all():
            raise ParameterError(f"neurons must be {rays.shape[0]} finite sizes, one per ray")
        if passes is not None and (isinstance(passes, bool) or not isinstance(passes, (int, np.integer))
                                   or passes < 1):
            raise ParameterError(f"passes must be a positive integer, got {passes!r}")
        lod = np.clip(lod, lo, hi)
        out = np.zeros((rays.shape[0], 4), np.float32)
        dt = torch.float16 if self.half else torch.float32
        x = torch.from_numpy(np.ascontiguousarray(rays, np.float32)).to(self.device, dt)
        keep = np.arange(rays.shape[0])
        if self.occ is not None and use_occupancy:
            keep = self._occupied(x).cpu().numpy()
        self.rays_evaluated += int(keep.size)
        top = np.minimum(np.ceil(lod[keep] - 1e-9), hi).astype(np.int64)
        if passes is None:
            distinct = np.unique(top).size
            whole = bool(np.all(lod[keep] == top))
            passes = distinct if whole and distinct <= MAX_SIZE_PASSES else 4
        for a, b in plan_passes(top, passes):
            sel = keep[(top >= a) & (top <= b)]
            step = self._batch(b)
            for c in range(0, sel.size, step):
                part = sel[c:c + step]
                t = torch.from_numpy(lod[part]).to(self.device, dt)
                out[part] = self.model.forward_lod(x[torch.from_numpy(part).to(self.device)], t).float().cpu().numpy()
        return out

    def _lod_map(self, lod) -> tuple[np.ndarray, float]:
        """(lod as float64 (h, w), its scale h / H), or a ParameterError: a 2-D map of the views'
        aspect within ``Limits.max_view_pixels``."""
        lod = np.asarray(lod, np.float64)
        if lod.ndim != 2 or min(lod.shape) < 1:
            raise ParameterError(f"lod must be an (h, w) map of sizes, got shape {lod.shape}")
        h, w = lod.shape
        if h * w > self._limits.max_view_pixels:
            raise ParameterError(f"a {h}x{w} lod map is over the {self._limits.max_view_pixels} pixels a view may have")
        scale = h / self.height
        if (round(self.height * scale), round(self.width * scale)) != (h, w):
            raise ParameterError(f"a {h}x{w} lod map is not the {self.height}x{self.width} views at one scale")
        if not np.isfinite(lod).all():
            raise ParameterError("lod must hold finite sizes")
        return lod, scale

    def render_lod_map(self, row: int, col: int, lod: np.ndarray, quantum: float | None = None,
                       passes: int | None = None) -> np.ndarray:
        """A view where pixel (y, x) is rendered with ``lod[y, x]`` (fractional) neurons, in at
        most ``passes`` network passes (:meth:`render_rays_lod`; None: its default); ``quantum``
        rounds the sizes first (None: exact). The view is rendered at the size of ``lod``: the
        views' (H, W), or any other (h, w) of the same aspect, e.g. a display's (the scale is
        h / H). Returns (h, w, 4) float32 RGBA (premultiplied)."""
        lod, scale = self._lod_map(lod)
        h, w = lod.shape
        rays = self.view_rays(row, col, scale).reshape(-1, 6)
        lod = lod.reshape(-1)
        if quantum:
            lod = np.round(lod / quantum) * quantum
        return self.render_rays_lod(rays, lod, passes).reshape(h, w, 4)

    def mip_levels(self, lod: np.ndarray, max_level: int = MIP_LEVELS) -> np.ndarray:
        """Per-pixel mip level of a size map (float64, same shape): log2 of how much coarser the
        image scale a size stands for (:meth:`LfnConfig.scale_of`) is than the largest held
        size's, within [0, ``max_level``] and the base network's level. 0 = every pixel drawn."""
        lo, hi = self.neuron_range
        per = self._levels_per_neuron()
        return np.clip((hi - np.clip(lod, lo, hi)) * per, 0.0, min(float(max_level), (hi - lo) * per))

    def _levels_per_neuron(self) -> float:
        """Mip levels (octaves of image scale) per neuron: :meth:`LfnConfig.scale_of` is
        log-linear from ``min_scale`` at the base network to 1 at the full one (0 if one size)."""
        c = self.cfg
        span = c.max_neurons - c.min_neurons
        return math.log2(1.0 / c.min_scale) / span if span else 0.0

    def mip_neurons(self, level: int) -> float:
        """The integer size a mip level's lattice is rendered with: the size made for the image
        scale 2^-(level − :data:`MIP_SHARPEN`) of the largest held size's (rounded up; the
        largest held size at level 0), within the held range."""
        lo, hi = self.neuron_range
        per = self._levels_per_neuron()
        if not per or level <= 0:
            return float(hi)
        return float(min(hi, max(lo, math.ceil(hi - max(level - MIP_SHARPEN, 0.0) / per - 1e-9))))

    def render_lod_mip(self, row: int, col: int, lod: np.ndarray, max_level: int = MIP_LEVELS,
                       blend: float = MIP_BLEND, bias: float = 0.0, native: bool = False) -> np.ndarray:
        """A view drawn from a size map with the sample density each size stands for, as
        mipmapping draws a texture: sizes are anti-aliased networks (size n is trained on the
        views box-filtered to :meth:`LfnConfig.scale_of` (n)), so a pixel whose size stands for
        1/2^m of the largest size's scale needs a sample only every 2^m pixels. Level j is a
        lattice every 2^j pixels rendered with the one integer size :meth:`mip_neurons` (j) (one
        fused pass per level, at most ``max_level`` + 1), only at the lattice points some pixel
        reads; each pixel takes the level below and above its :meth:`mip_levels` value ``m``
        (plus :data:`MIP_OFFSET`), each upsampled bilinearly, and blends them linearly over the
        middle ``blend`` of the interval between them (1 = trilinear filtering; the default 0.25
        blends over a quarter and takes one level elsewhere, which halves the rays of the
        full-density level, still without steps or dither noise). Level j runs a size one
        octave finer than its stride (:data:`MIP_SHARPEN`, :meth:`mip_neurons`). ``bias`` is
        added to ``m`` (> 0: coarser and faster, as a texture's LOD bias). Where the map is the
        full network the pixels are exactly :meth:`render`'s (``native=True``: every lattice
        :meth:`native_stride` times sparser, each pixel at the same size, and the fovea exactly
        ``render(native=True)``'s). ``lod`` as in
        :meth:`render_lod_map`, e.g. ``foveation_map(gaze, dither=False)``: on one CPU thread
        about 0.3-0.65x a full render's time, closer to the captured views than the dithered
        map's render and without its pixel noise (BENCHMARKS.md).

        Returns:
            (h, w, 4) float32 RGBA (premultiplied), (h, w) = ``lod``'s shape.
        """
        self._check_view(row, col)
        lod, scale = self._lod_map(lod)
        return self._render_mip(lod, scale, self._view_rays_at(row, col, scale), max_level, blend, bias, native)

    def _view_rays_at(self, row: int, col: int, scale: float):
        """``rays_at(size, spacing, at)`` of captured view (row, col) rendered at ``scale``
        (:func:`camera_rays`' arguments; a bad camera in the file is a FormatError)."""
        def rays_at(size, spacing, at):
            try:
                return view_rays(self.geom, row * self.cols + col, scale, self.norm["centre"], self.norm["radius"],
                                 size, spacing, at)
            except ParameterError as e:              # the file's own camera and intrinsics
                raise FormatError(f"{self.file.container.name}: view ({row},{col}): {e}") from None
        return rays_at

    def _pose_rays_at(self, c2w: np.ndarray, scale: float):
        """``rays_at(size, spacing, at)`` of a checked camera pose rendered at ``scale``."""
        g = self._intr
        return lambda size, spacing, at: camera_rays(c2w, g.focal, g.principal, g.height, g.width, scale,
                                                     self.norm["centre"], self.norm["radius"], size, spacing, at)

    def render_pose_lod_mip(self, c2w, lod: np.ndarray, max_level: int = MIP_LEVELS, blend: float = MIP_BLEND,
                            bias: float = 0.0, native: bool = False) -> np.ndarray:
        """:meth:`render_lod_mip` from any camera pose (as :meth:`render_pose`): a foveated frame
        for a headset's eye, e.g. ``render_pose_lod_mip(eye, foveation_map(gaze, dither=False,
        scale=S))``."""
        c2w = self._check_pose(c2w, self.norm)
        lod, scale = self._lod_map(lod)
        return self._render_mip(lod, scale, self._pose_rays_at(c2w, scale), max_level, blend, bias, native)

    @torch.no_grad()
    def _render_mip(self, lod: np.ndarray, scale: float, rays_at, max_level, blend, bias, native) -> np.ndarray:
        """The mip render of :meth:`render_lod_mip`; ``rays_at(size, spacing, at)`` gives the (M, 6)
        rays of a lattice's points ``at`` (:func:`camera_rays`' arguments)."""
        if isinstance(max_level, bool) or not isinstance(max_level, (int, np.integer)) or not 0 <= max_level <= 8:
            raise ParameterError(f"max_level must be an integer in 0..8, got {max_level!r}")
        check_numbers(blend=blend, bias=bias)
        if not (0 <= blend <= 1 and -8 <= bias <= 8):
            raise ParameterError(f"blend must be within [0, 1] and bias within [-8, 8], got {blend!r}, {bias!r}")
        h, w = lod.shape
        # native: every lattice as many octaves sparser as the frame is finer than the network
        # (render(native=True)'s stride); each pixel keeps its network size
        shift = int(self.native_stride(self.neuron_range[1], scale)).bit_length() - 1 if native else 0
        m = np.clip(self.mip_levels(lod, int(max_level)) + (MIP_OFFSET + bias), 0.0, float(max_level)) + shift
        lower = np.floor(m)
        f = m - lower
        # the upper level's share: linear over the middle `blend` of each interval (1: trilinear)
        up = np.clip((f - 0.5) / blend + 0.5, 0.0, 1.0) if blend > 0 else (f >= 0.5).astype(np.float64)
        lower = lower.astype(np.int8)
        w_lo, w_up = (1.0 - up).astype(np.float32), up.astype(np.float32)   # (a pixel's two levels' shares)
        out = np.zeros((h, w, 4), np.float32)
        for j in range(int(lower.max()) + 2):
            wt = np.where(lower == j, w_lo, np.where(lower == j - 1, w_up, np.float32(0)))
            used = wt > 0
            rows, cols = np.flatnonzero(used.any(1)), np.flatnonzero(used.any(0))
            if rows.size == 0:
                continue
            box = np.s_[rows[0]:rows[-1] + 1, cols[0]:cols[-1] + 1]      # where this level has weight
            if j == 0:
                y, x = np.nonzero(used[box])
                at = (y + rows[0]) * w + (x + cols[0])
                img = np.zeros(used[box].shape + (4,), np.float32)
                pixels = rays_at((h, w), (h / self.height, w / self.width), at)
                img[y, x] = self.render_rays(pixels, self.mip_neurons(0))
                img *= wt[box][..., None]
                out[box] += img
                continue
            img, keep = self._lattice(1 << j, used, self.mip_neurons(j - shift), rays_at)
            wb = wt[box] if keep is None else wt[box] * keep[box]     # the silhouette's cut folded in
            img = img[box]
            img *= wb[..., None]
            out[box] += img
        return out

    @torch.no_grad()
    def _lattice(self, k: int, used: np.ndarray, neurons: float, rays_at) -> tuple[np.ndarray, np.ndarray | None]:
        """Pixels read bilinearly from a lattice every ``k`` pixels (k > 1) rendered at ``neurons``,
        valid where ``used`` (h, w) is set: the network runs only at the lattice points those
        pixels' taps read. ``rays_at(size, spacing, at)`` as in :meth:`_render_mip`.

        Returns:
            ((h, w, 4) float32 RGBA, the upsampled lattice; (h, w) bool, the pixels inside the
            silhouette (cut per pixel: multiply the image by it), or None without an occupancy
            net)."""
        h, w = used.shape
        hj, wj = -(-h // k), -(-w // k)
        dt = torch.float16 if self.half else torch.float32
        # the lattice points a used pixel's bilinear taps read: its k×k block's and the
        # neighbours' (a pixel's sample position lies within half a lattice step of its block)
        need = np.zeros((hj * k, wj * k), np.uint8)
        need[:h, :w] = used
        need = cv2.dilate(need, np.ones((k, k), np.uint8), anchor=(0, 0))[::k, ::k]   # any of each k×k block
        need = cv2.dilate(need, np.ones((3, 3), np.uint8)).view(bool)
        cand = np.flatnonzero(need)
        rays = rays_at((hj, wj), (h / (self.height * k), w / (self.width * k)), cand)
        inside = None
        if self.occ is not None:
            # the occupancy net's cut is sharp, and upsampled from a lattice it would be drawn as
            # stairs: the network runs at the lattice points next to an occupied one too (colour
            # to upsample up to the silhouette), and the silhouette is cut per pixel below, asking
            # the occupancy net only where the lattice's answer is mixed
            inside = np.zeros(hj * wj, np.uint8)
            inside[cand[self._occupied(torch.from_numpy(rays).to(self.device, dt)).cpu().numpy()]] = 1
            inside = inside.reshape(hj, wj)
            sel = cv2.dilate(inside, np.ones((3, 3), np.uint8)).view(bool).reshape(-1)[cand]
            cand, rays = cand[sel], np.ascontiguousarray(rays[sel])
        img = np.zeros((hj * wj, 4), np.float32)
        img[cand] = self.render_rays(rays, neurons, use_occupancy=False)
        # OpenCV's pixel-centre convention: pixel y samples the lattice at (y + 0.5)/k − 0.5
        img = cv2.resize(img.reshape(hj, wj, 4), (wj * k, hj * k), interpolation=cv2.INTER_LINEAR)[:h, :w]
        if inside is None:
            return img, None
        frac = cv2.resize(inside.astype(np.float32), (wj * k, hj * k), interpolation=cv2.INTER_LINEAR)[:h, :w]
        keep = frac > 1 - 1e-4                                  # every tap occupied
        mixed = np.flatnonzero(used & ~keep & (frac > 1e-4))
        if mixed.size:
            x = torch.from_numpy(rays_at((h, w), (h / self.height, w / self.width), mixed)).to(self.device, dt)
            keep.reshape(-1)[mixed[self._occupied(x).cpu().numpy()]] = True
        return img, keep

    def foveation_map(self, gaze: tuple[float, float], inner: float = 0.1, outer: float = 0.5,
                      dither: bool = True, sizes: int = 8, frame: int = 0, scale: float = 1.0) -> np.ndarray:
        """Per-pixel network sizes (h, w) around a gaze point (x, y in pixels of the map): the full
        network inside ``inner``·diag, falling linearly to the base network at ``outer``·diag. The
        map is the views' size times ``scale`` (a display's resolution; :meth:`render_lod_map`
        renders at the map's size).

        - ``dither=True`` (default): each pixel takes one of ``sizes`` integer sizes (evenly
          spaced from the base to the full network): between two of them, the upper where the
          pixel's position between them exceeds an interleaved-gradient-noise threshold
          (:func:`dither_threshold`, shifted by ``frame``: advance it per frame and the noise
          averages out). :meth:`render_lod_map` runs one fused pass per size (0.54-0.81x a full
          render on one CPU thread, BENCHMARKS.md), without arcs but with pixel-scale noise.
        - ``dither=False``: fractional sizes. :meth:`render_lod_mip` (or :meth:`render_pose_lod_mip`)
          draws them with fewer samples where the network is coarser: the fastest form (0.28-0.69x
          a full render on one CPU thread), continuous, without pixel noise.
          :meth:`render_lod_map` renders every pixel at its exact size: no pixel noise, but the
          nested networks' differences from one size to the next show as faint arcs around the
          gaze, and the weighted LayerNorm of fractional sizes costs on a CPU about what it saves.
        """
        h, w = self._scaled(scale)
        if not (np.isfinite(gaze).all() and np.size(gaze) == 2):
            raise ParameterError(f"gaze must be a finite (x, y) in pixels, got {gaze!r}")
        if not (np.isfinite(inner) and np.isfinite(outer) and 0 <= inner <= outer):
            raise ParameterError(f"inner and outer must be finite with 0 <= inner <= outer, got {inner!r}, {outer!r}")
        ys, xs = np.mgrid[0:h, 0:w] + 0.5
        diag = float(np.hypot(h, w))
        e = np.hypot(xs - gaze[0], ys - gaze[1]) / diag
        t = np.clip((e - inner) / max(outer - inner, 1e-9), 0, 1)
        lo, hi = self.neuron_range
        lod = np.clip(hi - t * (hi - lo), lo, hi)
        if not dither:
            return lod
        if isinstance(sizes, bool) or not isinstance(sizes, (int, np.integer)) or not 1 <= sizes <= MAX_SIZE_PASSES:
            raise ParameterError(f"sizes must be an integer in 1..{MAX_SIZE_PASSES}, got {sizes!r}")
        return dither_sizes(lod, size_levels(lo, hi, int(sizes)), dither_threshold(h, w, frame))
