"""Rendering from an LFN stream (or any prefix of it): a view at a fractional network size, or
with a per-pixel size map (foveation, dithered transitions: :mod:`lfn_stream.foveation`), in
batches; fp32 on CPU, fp16 on GPU. :class:`LfnRenderer` is also the codec's :class:`~formats.codec_api.Decoder`: level 0 is
the full network, level L the network with L fewer (fractional) neurons per layer.
"""
from __future__ import annotations

import math

import numpy as np
import torch

from formats.codec_api import Decoder, check_integers, check_numbers
from formats.devices import torch_device
from formats.errors import FormatError, ParameterError, UnsupportedError
from formats.lfcfile import LfcFile

from .foveation import Foveated
from .pack import unpack_network
from .stream import LfnStream
from .cameras import grid_pose, orbit_pose, scene_pivot, stereo_poses
from .rays import camera_rays, view_rays

ALPHA_MIN = 2.0 ** -20   # below it a pixel's colour is 0 (invisible at 16 bits; exact in float32 and float64)

OCC_BATCH = 4096    # rays per occupancy-net call on a CPU: 512 KiB of activations (16384: 2x slower, 65536: ~8x)


class LfnRenderer(Foveated, LfnStream, Decoder):
    """Renderer over an opened .lfc file holding an LFN stream (possibly a prefix of it): the
    stream as :class:`~lfn_stream.stream.LfnStream` reads and checks it, and its network built
    (torch) on ``device``.

    Attributes:
        cfg: the full network's config; neurons: the largest network the available bytes give.
        rows, cols, height, width, channels, dtype: the light field's geometry (pixels).
        levels: the coarsest level (neurons − min_neurons; levels are fractional).
        prefetch: over a network (a URL), after each read of steps the next ``prefetch``
            neurons' steps are fetched in the background (version 3 files), so that
            :meth:`grow` finds them local; 0 turns it off.
    """

    def __init__(self, f: LfcFile, device: str | None = None, max_neurons: float | None = None, *, limits=None,
                 prefetch: int = 16):
        self._device_arg = device
        self.rays_evaluated = 0   # network evaluations so far (rays the occupancy net let through)
        super().__init__(f, max_neurons, limits=limits, prefetch=prefetch)

    def _check_weights(self) -> None:
        """The network built on the device from the steps held (:meth:`_build` checks their
        weights as :class:`LfnStream` does)."""
        self.device = torch_device(self._device_arg)
        self.half = self.device.type == "cuda"
        self._build()

    def _batch(self, neurons: float) -> int:
        """Rays per network call: on a CPU, activations of about 2^18 values (1 MiB: 2048 rays
        at 128 neurons) stay in cache and run ~6x faster than 65536-ray batches at 128 neurons;
        on a GPU, 65536 rays."""
        if self.device.type == "cuda":
            return 65536
        return int(np.clip(2 ** 18 // max(int(np.ceil(neurons)), 1), 2048, 65536))

    def _occupied(self, x: torch.Tensor) -> torch.Tensor:
        """Indices (M,) of the rays x (N, 6) that the occupancy net lets through (sigmoid > 0.1),
        in calls of OCC_BATCH rays (65536 on a GPU)."""
        step = 65536 if self.device.type == "cuda" else OCC_BATCH
        return torch.cat([torch.nonzero(torch.sigmoid(self.occ(x[a:a + step]).float()) > 0.1)[:, 0] + a
                          for a in range(0, x.shape[0], step)] or [torch.zeros(0, dtype=torch.long, device=x.device)])

    def _build(self) -> None:
        self.model, self.occ = unpack_network(self.cfg, self._base, self._steps, self._occ_bytes, self.dtype_w)
        self.model.to(self.device).eval()
        if self.occ is not None:
            self.occ.to(self.device).eval()
        if self.half:
            self.model.half()
            if self.occ is not None:
                self.occ.half()

    def grow(self, max_neurons: float | None = None) -> float:
        """Progressive streaming: read the next sections (over HTTP, only their bytes) so that
        the network has up to ``max_neurons`` neurons per layer (None = all the file has), and
        rebuild it; returns the neurons now available. Rendering at a level the grown network
        shares gives the same pixels as a renderer opened with that many neurons."""
        limit = self.cfg.max_neurons if max_neurons is None else max_neurons
        if isinstance(limit, bool) or not isinstance(limit, (int, float, np.integer, np.floating)) \
                or not np.isfinite(limit) or limit < self.cfg.min_neurons:
            raise ParameterError(f"max_neurons must be a number >= {self.cfg.min_neurons}, got {max_neurons!r}")
        n = len(self._steps)
        self._read_steps(int(np.ceil(min(limit, self.cfg.max_neurons))))
        if len(self._steps) != n:
            self._build()
        return float(self.neurons)

    @property
    def neuron_range(self) -> tuple[float, float]:
        return float(self.cfg.min_neurons), float(self.neurons)

    def neurons_at(self, level: float) -> float:
        """Neurons of a level (0 = the largest available network)."""
        if isinstance(level, bool) or not isinstance(level, (int, float, np.integer, np.floating)) \
                or not 0 <= level <= self.levels:
            raise ParameterError(f"level must be within 0..{self.levels:g} (0 = the full network, {self.levels:g} = "
                                 f"the base network), got {level!r}")
        return float(self.neurons - level)

    def _scaled(self, scale) -> tuple[int, int]:
        """(h, w) of the views at ``scale``, or a ParameterError: a finite number in (0, 64] that
        leaves at least one pixel and at most ``Limits.max_view_pixels``."""
        if isinstance(scale, bool) or not isinstance(scale, (int, float, np.integer, np.floating)) \
                or not 0 < scale <= 64:
            raise ParameterError(f"scale must be within (0, 64], got {scale!r}")
        h, w = round(self.height * scale), round(self.width * scale)
        if h < 1 or w < 1:
            raise ParameterError(f"scale {scale} leaves no pixels of the {self.height}x{self.width} views")
        if h * w > self._limits.max_view_pixels:
            raise ParameterError(f"scale {scale} makes a {h}x{w} view, over the {self._limits.max_view_pixels} pixels "
                                 f"a view may have (Limits.max_view_pixels)")
        return h, w

    def _check(self, neurons: float) -> float:
        lo, hi = self.neuron_range
        if isinstance(neurons, bool) or not isinstance(neurons, (int, float, np.integer, np.floating)) \
                or not lo <= neurons <= hi:
            raise ParameterError(f"{neurons!r} neurons outside the available range [{lo:g}, {hi:g}]")
        return float(neurons)

    @torch.no_grad()
    def render_rays(self, rays: np.ndarray, neurons: float, batch: int | None = None,
                    use_occupancy: bool = True) -> np.ndarray:
        """(N, 6) Plücker rays → (N, 4) RGBA in [0, 1] (premultiplied), skipping empty rays
        (those the occupancy net rejects, when the stream has one and ``use_occupancy``): the
        occupancy net runs first over all the rays, then the network over the rays it let
        through, in calls of ``batch`` rays (default :meth:`_batch`: full calls whatever the
        share of empty rays)."""
        neurons = self._check(neurons)
        if batch is not None:
            check_integers(batch=batch)
            if batch < 1:
                raise ParameterError(f"batch must be a positive number of rays, got {batch!r}")
        batch = batch or self._batch(neurons)
        out = np.zeros((rays.shape[0], 4), np.float32)
        dt = torch.float16 if self.half else torch.float32
        x = torch.from_numpy(rays).to(self.device, dt)
        idx = None
        if self.occ is not None and use_occupancy:
            idx = self._occupied(x)                   # the occupancy net really skips rays
            x = x[idx]
        self.rays_evaluated += int(x.shape[0])
        if x.shape[0]:
            rgba = torch.cat([self.model(x[a:a + batch], neurons) for a in range(0, x.shape[0], batch)])
            out[slice(None) if idx is None else idx.cpu().numpy()] = rgba.float().cpu().numpy()
        return out

    def _check_view(self, row: int, col: int) -> None:
        """A ParameterError unless (row, col) are integers naming a captured view."""
        check_integers(row=row, col=col)
        if not (0 <= row < self.rows and 0 <= col < self.cols):
            raise ParameterError(f"view ({row},{col}) is outside the {self.rows}x{self.cols} grid")

    def view_rays(self, row: int, col: int, scale: float = 1.0) -> np.ndarray:
        self._check_view(row, col)
        self._scaled(scale)
        try:
            return view_rays(self.geom, row * self.cols + col, scale, self.norm["centre"], self.norm["radius"])
        except ParameterError as e:                  # the file's own camera and intrinsics
            raise FormatError(f"{self.file.container.name}: view ({row},{col}): {e}") from None

    def render(self, row: int, col: int, neurons: float | None = None, scale: float | None = None,
               native: bool = False) -> np.ndarray:
        """One view with a (fractional) network size (default: :meth:`display_neurons_at` the
        scale asked for, else :attr:`display_neurons`); scale defaults to the size's own (1/8 … 1).
        ``native=True``: where the render is finer than the network holds (a network trained at
        reduced resolution, :attr:`native_scale`), the network runs on a lattice every
        :meth:`native_stride` pixels, upsampled bilinearly with the silhouette cut per pixel
        (at stride 2: 0.2-0.3x the time, within 0.05 dB of the dense render against the
        captured views, BENCHMARKS.md).

        Returns:
            (h, w, 4) float32 RGBA (premultiplied) in [0, 1].
        """
        neurons = self.display_neurons_at(scale) if neurons is None else self._check(neurons)
        scale = self.cfg.scale_of(neurons) if scale is None else scale
        if native and self.native_stride(neurons, scale) > 1:
            self._check_view(row, col)
            return self._render_native(neurons, scale, self._view_rays_at(row, col, scale))
        rays = self.view_rays(row, col, scale)
        h, w = rays.shape[:2]
        return self.render_rays(rays.reshape(-1, 6), neurons).reshape(h, w, 4)

    @property
    def native_scale(self) -> float:
        """The scale of the views the full network was trained at, as the file's display ladders
        state it (the encoder measures them at the training views' scale and at its 1/2, 1/4 and
        1/8: the largest is that scale); 1 for a file without them."""
        return min(1.0, self.display_scales[-1][0]) if self.display_scales else 1.0

    def native_stride(self, neurons: float, scale: float) -> int:
        """Pixels between network samples for ``native=True`` renders of ``neurons`` at ``scale``:
        the largest power of two up to 8 within how much finer the render is than the network's
        own scale (:attr:`native_scale` × :meth:`LfnConfig.scale_of`)."""
        check_numbers(neurons=neurons, scale=scale)
        over = float(scale) / (self.native_scale * self.cfg.scale_of(float(neurons)))
        return int(2 ** min(3, max(0, math.floor(math.log2(over) + 1e-9)))) if over > 0 else 1

    def _render_native(self, neurons: float, scale: float, rays_at) -> np.ndarray:
        """The ``native=True`` render: every pixel from the lattice of :meth:`native_stride`."""
        h, w = self._scaled(scale)
        img, keep = self._lattice(self.native_stride(neurons, scale), np.ones((h, w), bool), neurons, rays_at)
        if keep is not None:
            img *= keep[..., None]
        return img

    # -- free cameras (lfn_stream.cameras; the browser viewer uses the same formulas) ---------
    def pose(self, row: int, col: int) -> np.ndarray:
        """4×4 camera-to-world matrix of a captured view (OpenGL axes, scene units)."""
        self._check_view(row, col)
        return self.poses[row, col].copy()

    def grid_pose(self, s: float, t: float) -> np.ndarray:
        """Pose at a continuous grid position (row s, column t): centres blended bilinearly, the
        nearest view's rotation."""
        return grid_pose(self.poses, float(s), float(t))

    def orbit_pose(self, row: int, col: int, yaw: float, pitch: float = 0.0) -> np.ndarray:
        """A captured view turned about the scene's pivot (the point nearest every optical axis):
        ``yaw`` degrees about the mean up vector, ``pitch`` degrees about the camera's right axis."""
        return self.turn_pose(self.pose(row, col), yaw, pitch)

    def turn_pose(self, pose: np.ndarray, yaw: float, pitch: float = 0.0) -> np.ndarray:
        """Any camera turned about the scene's pivot, as :meth:`orbit_pose` turns a captured view."""
        check_numbers(yaw=yaw, pitch=pitch)
        pivot, up = scene_pivot(self.poses, self.norm["centre"])
        return orbit_pose(self._check_pose(pose), pivot, up, float(yaw), float(pitch))

    def stereo_poses(self, pose: np.ndarray, ipd: float) -> tuple[np.ndarray, np.ndarray]:
        """(left, right) poses ``ipd`` scene units apart along ``pose``'s x axis."""
        check_numbers(ipd=ipd)
        return stereo_poses(self._check_pose(pose), float(ipd))

    def render_pose(self, c2w, neurons: float | None = None, scale: float | None = None,
                    native: bool = False) -> np.ndarray:
        """A view from any camera pose (4×4 camera-to-world, OpenGL axes, scene units) with the
        captured views' intrinsics; neurons, scale and native as in :meth:`render`.

        Returns:
            (h, w, 4) float32 RGBA (premultiplied) in [0, 1].
        """
        c2w = self._check_pose(c2w, self.norm)
        neurons = self.display_neurons_at(scale) if neurons is None else self._check(neurons)
        scale = self.cfg.scale_of(neurons) if scale is None else scale
        self._scaled(scale)
        if native and self.native_stride(neurons, scale) > 1:
            return self._render_native(neurons, scale, self._pose_rays_at(c2w, scale))
        g = self._intr
        rays = camera_rays(c2w, g.focal, g.principal, g.height, g.width, scale, self.norm["centre"], self.norm["radius"])
        h, w = rays.shape[:2]
        return self.render_rays(rays.reshape(-1, 6), neurons).reshape(h, w, 4)

    # -- the Decoder interface ---------------------------------------------------------------
    def to_pixels(self, rgba: np.ndarray) -> np.ndarray:
        peak = float(np.iinfo(self.dtype).max)
        a = np.clip(rgba, 0, 1)
        if self.channels in (2, 4):          # un-premultiply where α ≥ 2^-20 (FORMAT.md), else colour 0
            alpha = a[..., 3:4]
            col = a[..., :self.channels - 1]
            px = np.concatenate([np.where(alpha >= ALPHA_MIN, col / np.maximum(alpha, ALPHA_MIN), 0), alpha], -1)
        elif self.channels == 1:
            px = a[..., :1]
        else:
            px = a[..., :3]
        return np.rint(np.clip(px, 0, 1) * peak).astype(self.dtype)

    def decode_view(self, row: int, col: int, level: float = 0) -> np.ndarray:
        """Full-size pixels of one view at a level (0 = the largest available network)."""
        return self.to_pixels(self.render(row, col, self.neurons_at(level), scale=1.0))

    def decode_block(self, *a, **k):
        raise UnsupportedError("block random access is an RLFC feature; an LFN renders rays (use --view)")
