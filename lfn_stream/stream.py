"""An LFN stream (or any prefix of it) read and checked without building its network: the
config, display ladders, cameras, the steps held and their weights (numpy only, no torch), and
what ``lfcodec info`` says of it. :class:`lfn_stream.render.LfnRenderer` builds on it.
"""
from __future__ import annotations

import math

import numpy as np

from formats.codec_api import check_numbers
from formats.errors import FormatError, ParameterError, TruncatedError
from formats.lfcfile import LfcFile, check_codec_version
from formats.lightfield import LightField, read_geometry
from formats.schema import Fields, read_vector

from .cameras import captured_poses
from .config import CODEC_ID, CODEC_VERSION, LfnConfig
from .pack import base_values, occ_values, step_bytes, step_name, step_offsets, unpack_arrays


def first_renderable_end(c) -> int:
    """Byte where the first renderable prefix of an LFN file's container ``c`` ends: its header,
    meta, base network and occupancy net (where it has one)."""
    names = ["lfn.base"] + (["lfn.occ"] if c.has("lfn.occ") else [])
    return max(c.info(nm).offset + c.info(nm).length for nm in names)


def prefix_bytes(r, level: float) -> int:
    """Bytes of the file prefix holding the network a level needs (header, meta, base,
    occupancy, steps; version 3: up to the end of the checksum chunk holding the last step) of
    an :class:`LfnStream` (a renderer too); of a tile set (:class:`lfn_stream.tiles.TiledLfnRenderer`),
    its own sum over the tiles."""
    if not isinstance(r, LfnStream):
        return r.prefix_bytes(level)
    c = r.file.container
    n = int(math.ceil(level - 1e-9)) - r.cfg.min_neurons
    end = first_renderable_end(c)
    if n <= 0:
        return end
    if c.has("lfn.steps"):
        s = c.info("lfn.steps")
        stop = int(step_offsets(r.cfg, r.dtype_w)[n])
        return s.offset + min(-(-stop // s.chunk_size) * s.chunk_size, s.length)
    return max(end, *(c.info(step_name(j)).offset + c.info(step_name(j)).length for j in range(n)))


class LfnStream:
    """An opened .lfc file holding an LFN stream (possibly a prefix of it), checked as
    :class:`~lfn_stream.render.LfnRenderer` checks it, without a network.

    Attributes:
        cfg: the full network's config; neurons: the largest network the available bytes give.
        rows, cols, height, width, channels, dtype: the light field's geometry (pixels).
        levels: the coarsest level (neurons − min_neurons; levels are fractional).
        prefetch: over a network (a URL), after each read of steps the next ``prefetch``
            neurons' steps are fetched in the background (version 3 files), so that a renderer's
            ``grow`` finds them local; 0 turns it off.
    """

    def __init__(self, f: LfcFile, max_neurons: float | None = None, *, limits=None, prefetch: int = 16):
        check_codec_version(f, CODEC_ID, CODEC_VERSION)
        if isinstance(prefetch, bool) or not isinstance(prefetch, (int, np.integer)) or prefetch < 0:
            raise ParameterError(f"prefetch must be a number of neurons >= 0, got {prefetch!r}")
        self.prefetch = int(prefetch)
        self.file = f
        c = f.container
        lim = self._limits = limits or f.limits     # the caller's, else those the file was opened with
        try:
            conf = Fields(f.meta, f"{c.name}: metadata").sub("config")
            self.cfg = LfnConfig.from_dict(conf.obj.get("network"), int(f.meta.get("codec_version", 1)))
            norm = conf.sub("norm")
            self.norm = {"centre": read_vector(norm.obj.get("centre"), 3, f"{c.name}: config.norm.centre"),
                         "radius": norm.float("radius", 1e-12, 1e12)}
            self.dtype_w = conf.str("weights", choices=("fp16", "fp32"), default="fp16")
            self.display = self._read_display(conf.obj.get("display"))
            self.display_scales = self._read_display_scales(conf.obj.get("display_scales"))
        except ParameterError as e:
            raise FormatError(f"{c.name}: lfn network config is invalid ({e})") from None
        scene = read_geometry(f.meta.get("scene"), f"{c.name}: scene", lim)
        if not c.available("lfn.base"):
            raise FormatError(f"{c.name}: the stream prefix does not hold the base network")
        # the intrinsics (in meta); the captured cameras may lie at the end of the file (meta.more)
        self.rows, self.cols = scene["rows"], scene["cols"]
        self.height, self.width, self.channels = scene["height"], scene["width"], scene["channels"]
        self._intr = self._geometry(f.meta["scene"])
        self._geom = None
        if scene["dtype"] not in ("uint8", "uint16"):
            raise FormatError(f"{c.name}: scene dtype must be uint8 or uint16 for an LFN, got {scene['dtype']}")
        self.dtype = np.dtype(scene["dtype"])
        # section sizes are checked against the config before any network is allocated
        itemsize = 2 if self.dtype_w == "fp16" else 4
        if c.info("lfn.base").length != base_values(self.cfg) * itemsize:
            raise FormatError(f"{c.name}: section 'lfn.base' has {c.info('lfn.base').length} bytes, the network "
                              f"config needs {base_values(self.cfg) * itemsize}")
        self._steps: list[bytes] = []
        self._packed = int(f.meta["codec_version"]) >= 3          # one lfn.steps section (version 3)
        if self._packed:
            self._offsets = step_offsets(self.cfg, self.dtype_w)
            if c.has("lfn.steps") and c.info("lfn.steps").length != self._offsets[-1]:
                raise FormatError(f"{c.name}: section 'lfn.steps' has {c.info('lfn.steps').length} bytes, the "
                                  f"network config needs {int(self._offsets[-1])}")
        self._read_steps(self.cfg.max_neurons if max_neurons is None else int(np.ceil(max_neurons)))
        occ = None
        if c.has("lfn.occ") and not c.available("lfn.occ"):
            # the occupancy net zeroes the rays it rejects: without it the pixels would differ from
            # the whole file's, so a prefix is renderable from the end of lfn.occ on (FORMAT.md)
            raise TruncatedError(f"{c.name}: the stream prefix ends inside the occupancy net (lfn.occ); the first "
                                 f"renderable prefix ends at byte {c.info('lfn.occ').offset + c.info('lfn.occ').length}")
        if c.has("lfn.occ") and self.cfg.occupancy_neurons:
            if c.info("lfn.occ").length != occ_values(self.cfg) * itemsize:
                raise FormatError(f"{c.name}: section 'lfn.occ' has {c.info('lfn.occ').length} bytes, the network "
                                  f"config needs {occ_values(self.cfg) * itemsize}")
            occ = bytes(c.read("lfn.occ"))
        self._base, self._occ_bytes = bytes(c.read("lfn.base")), occ
        self._check_weights()
        if not c.is_remote and (not f.moved or c.available("meta.more")):
            self.geom                  # noqa: B018 -- a local file's cameras are checked when it opens

    def _check_weights(self) -> None:
        """The held network's weights read and checked (numpy: :func:`unpack_arrays`)."""
        unpack_arrays(self.cfg, self._base, self._steps, self._occ_bytes, self.dtype_w)

    @property
    def neurons(self) -> int:
        """Neurons per layer of the largest network the steps held make."""
        return self.cfg.min_neurons + len(self._steps)

    @property
    def levels(self) -> float:
        """The coarsest level: neurons − min_neurons."""
        return float(len(self._steps))

    def _read_display(self, val) -> list[int] | None:
        """``config.display`` (FORMAT.md): strictly increasing integer sizes from min_neurons to
        max_neurons, or absent (None: every size is shown)."""
        if val is None:
            return None
        c = self.cfg
        if not self._is_ladder(val) or val[-1] != c.max_neurons:
            raise ParameterError(f"display must be increasing integer sizes from {c.min_neurons} to "
                                 f"{c.max_neurons}")
        return val

    def _is_ladder(self, val) -> bool:
        """A display ladder's shape (FORMAT.md): a list of strictly increasing integer sizes from
        min_neurons, none above max_neurons."""
        c = self.cfg
        return isinstance(val, list) and 1 <= len(val) <= c.max_neurons - c.min_neurons + 1 \
            and all(isinstance(w, int) and not isinstance(w, bool) for w in val) \
            and val[0] == c.min_neurons and val[-1] <= c.max_neurons and all(b > a for a, b in zip(val, val[1:]))

    def _read_display_scales(self, val) -> list[tuple[float, list[int]]] | None:
        """``config.display_scales`` (FORMAT.md): 1..16 pairs [scale, ladder], scales strictly
        increasing within (0, 64], each ladder strictly increasing integer sizes from min_neurons
        up to at most max_neurons; or absent (None)."""
        if val is None:
            return None
        c = self.cfg
        bad = ParameterError(f"display_scales must be 1 to 16 pairs [scale, sizes], scales increasing within "
                             f"(0, 64], sizes increasing integers from {c.min_neurons} up to {c.max_neurons}")
        if not isinstance(val, list) or not 1 <= len(val) <= 16:
            raise bad
        out = []
        for pair in val:
            if not isinstance(pair, list) or len(pair) != 2:
                raise bad
            sc, lad = pair
            if isinstance(sc, bool) or not isinstance(sc, (int, float)) or not 0 < sc <= 64 \
                    or (out and sc <= out[-1][0]):
                raise bad
            if not self._is_ladder(lad):
                raise bad
            out.append((float(sc), lad))
        return out

    def display_ladder_at(self, scale: float | None = None) -> list[int] | None:
        """The display ladder for rendering at ``scale`` (of the views): the file's ladder measured
        at the display scale nearest ``scale`` in ratio (``config.display_scales``; the smaller
        on a tie), else ``config.display`` (without ``scale`` too); None when the file has none."""
        if scale is None or self.display_scales is None:
            return self.display
        check_numbers(scale=scale)
        if not scale > 0:
            raise ParameterError(f"scale must be > 0, got {scale!r}")
        return min(self.display_scales, key=lambda p: abs(math.log(p[0] / float(scale))))[1]

    def display_neurons_at(self, scale: float | None = None) -> float:
        """The size to show from the bytes held when rendering at ``scale``: the largest size of
        :meth:`display_ladder_at` that the held steps reach, so that quality at that scale does
        not fall as bytes arrive and a size made for finer scales is not shown where it is
        worse. Without ``scale``, or for a file without per-scale ladders: :attr:`display_neurons`."""
        lad = self.display_ladder_at(scale)
        return float(self.neurons) if lad is None else float(max(w for w in lad if w <= self.neurons))

    @property
    def display_neurons(self) -> float:
        """The size to show from the bytes held: the largest size of the file's display ladder
        (``config.display``: sizes the encoder measured to beat every smaller one) that the
        held steps reach, so quality does not fall as bytes arrive; without a ladder, every
        held neuron. What :meth:`render` and :meth:`render_pose` use when no size and no scale is
        given."""
        return self.display_neurons_at(None)

    def _geometry(self, scene: dict) -> LightField:
        """Geometry only: a zero-stride placeholder of the views' shape (no pixel memory; the
        shape as validated at open, under the caller's limits)."""
        shape = (self.rows, self.cols, self.height, self.width, 1)
        return LightField.from_geometry(np.broadcast_to(np.zeros((1,) * 5, np.uint8), shape), scene,
                                        limits=self._limits)

    @property
    def geom(self) -> LightField:
        """The captured views' geometry, cameras included: read (for a remote file, fetched)
        from ``meta.more`` on first use in version 3 files, and checked (FORMAT.md)."""
        if self._geom is None:
            name = self.file.container.name
            geom = self._geometry(self.file.scene)
            poses = captured_poses(geom.positions, geom.c2w)       # (R, C, 4, 4) camera-to-world
            for pose in poses.reshape(-1, 4, 4):
                try:
                    self._check_pose(pose, self.norm)
                except ParameterError as e:
                    raise FormatError(f"{name}: a captured camera is unusable ({e})") from None
            self._geom, self._poses = geom, poses
        return self._geom

    @property
    def poses(self) -> np.ndarray:
        """(R, C, 4, 4) camera-to-world matrices of the captured views (OpenGL axes)."""
        self.geom                      # noqa: B018
        return self._poses

    def _read_steps(self, limit: int) -> None:
        """Read (fetch, for a remote file) the steps after those held, up to a network of
        ``limit`` neurons or the end of the available bytes; sizes checked first."""
        c = self.file.container
        if self._packed:
            if not c.has("lfn.steps"):
                return
            have, off = c.available_bytes("lfn.steps"), self._offsets
            k0 = len(self._steps)
            last = int(np.searchsorted(off, have, side="right")) - 1      # steps the available bytes hold
            k1 = min(last, max(limit - self.cfg.min_neurons, 0))
            if k1 > k0:
                data = bytes(c.read("lfn.steps", int(off[k0]), int(off[k1])))
                self._steps += [data[off[k] - off[k0]:off[k + 1] - off[k0]] for k in range(k0, k1)]
            if self.prefetch and k1 < last:               # the next steps, in the background
                c.prefetch("lfn.steps", int(off[k1]), int(off[min(k1 + self.prefetch, last)]))
            return
        for j in range(len(self._steps), self.cfg.max_neurons - self.cfg.min_neurons):
            if self.cfg.min_neurons + j >= limit or not c.available(step_name(j)):
                break
            want = step_bytes(self.cfg, self.cfg.min_neurons + j, self.dtype_w)
            if c.info(step_name(j)).length != want:
                raise FormatError(f"{c.name}: section {step_name(j)!r} has {c.info(step_name(j)).length} bytes, the "
                                  f"network config needs {want}")
            self._steps.append(bytes(c.read(step_name(j))))

    @staticmethod
    def _check_pose(c2w, norm=None) -> np.ndarray:
        """A usable camera (FORMAT.md): finite 4×4, rotation entries within ±2^20 and invertible,
        origin within 2^20 scene radii of the centre (so rays are finite in float32)."""
        try:
            a = np.asarray(c2w, dtype=np.float64)
        except (TypeError, ValueError):
            a = np.zeros(0)
        if a.shape != (4, 4) or not np.isfinite(a).all() or np.abs(a[:3, :3]).max() > 2 ** 20 \
                or abs(np.linalg.det(a[:3, :3])) < 1e-9:
            raise ParameterError("a camera pose must be a finite 4x4 camera-to-world matrix with an invertible rotation")
        if norm is not None and np.abs((a[:3, 3] - norm["centre"]) / norm["radius"]).max() > 2 ** 20:
            raise ParameterError("a camera lies more than 2^20 scene radii from the scene's centre")
        return a

    def info(self) -> dict:
        c = self.cfg
        first = prefix_bytes(self, c.min_neurons)       # header, meta, base network (+ occupancy net)
        return {"codec": CODEC_ID, "levels": self.levels, "network": c.to_dict(), "weights": self.dtype_w,
                "neurons_available": self.neurons, "display": self.display,
                "display_scales": self.display_scales, "first_renderable_bytes": first,
                "summary": f"light field network, depth {c.depth}, {c.min_neurons}..{c.max_neurons} neurons per "
                           f"layer ({self.neurons} in the available bytes); levels 0..{self.levels:g} (0 = full "
                           f"network; any prefix ending after a step is a complete network; the first renderable "
                           f"one is {first} bytes), {self.dtype_w} weights" + (
                               "" if self.display is None else
                               f"; display ladder of {len(self.display)} sizes (shown from these bytes: "
                               f"{self.display_neurons:g})") + (
                               "" if self.display_scales is None else
                               "; at display scale " + ", ".join(f"{sc:g}: {self.display_neurons_at(sc):g}"
                                                                 for sc, _ in self.display_scales))}
