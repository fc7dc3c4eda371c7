"""Tiled light field networks: submodels over camera space (SMERF's idea, for LFNs).

One network must model every ray of a capture; on a wide or sparse capture its neurons are
spread over rays no single camera sees. A tile set splits camera space into K regions (k-means
of the camera centres) and trains one ordinary LFN per region, each on the training cameras
that region is blended at (its own cameras and those within the blend band of it, so that
neighbouring submodels agree where they meet). Each submodel is an ordinary LFN ``.lfc`` file,
a progressive stream on its own (any prefix a smaller network; a URL opens it by byte ranges).

Blending: a camera at centre p with distances d_k to the tile centres renders the tiles with
d_k < (1 + band)·d_min, each weighted ∝ (1 + band)·d_min − d_k (premultiplied RGBA summed):
the weights change continuously with p, a camera near a tile centre renders that tile alone,
and a captured training camera is only ever rendered by tiles that trained on it.

The manifest (``*.json``, :data:`FORMAT_ID`, version 1) is small JSON::

    {"format": "lfcodec-lfn-tiles", "version": 1, "band": 0.5,
     "tiles": [{"file": "scene.tile00.lfc", "centre": [x, y, z], "views": [0, 1, ...]}, ...]}

``file`` names are relative to the manifest (a plain name or sub-path; no scheme, no absolute
path, no ``..``); ``centre`` is in scene units; ``views`` the flat indices it trained on.
"""
from __future__ import annotations

import dataclasses
import json
import math
import os
import re
from pathlib import Path

import numpy as np

from formats.codec_api import Decoder
from formats.errors import FormatError, LfcError, ParameterError, UnsupportedError

FORMAT_ID = "lfcodec-lfn-tiles"
FORMAT_VERSION = 1
MAX_TILES = 64
MAX_MANIFEST_BYTES = 1 << 20
DEFAULT_BAND = 0.5
_NAME = re.compile(r"^[A-Za-z0-9._-]+(/[A-Za-z0-9._-]+)*$")


def blend_weights(centres: np.ndarray, p: np.ndarray, band: float) -> np.ndarray:
    """(K,) float64 weights, summing to 1, of the tiles with centres (K, 3) for a camera at p (3,)
    (module docstring): tiles with d_k < (1 + band)·d_min, each ∝ (1 + band)·d_min − d_k."""
    d = np.linalg.norm(np.asarray(centres, np.float64) - np.asarray(p, np.float64)[None], axis=1)
    dmin = float(d.min())
    scale = float(np.linalg.norm(np.ptp(centres, axis=0))) or 1.0
    reach = (1.0 + band) * dmin + 1e-9 * scale        # > d_min: the nearest tile always has weight
    w = np.maximum(reach - d, 0.0)
    return w / w.sum()


def partition_cameras(centres: np.ndarray, k: int, band: float = DEFAULT_BAND, iters: int = 50):
    """Split camera centres (N, 3) into ``k`` regions by k-means (deterministic: farthest-point
    start from the camera nearest the mean).

    Returns:
        (tile centres (k', 3) float64, members: list of k' int64 arrays of camera indices, each
        the cameras a tile is blended at, its own included); k' ≤ k (regions left empty drop).
    """
    x = np.asarray(centres, np.float64).reshape(-1, 3)
    n = x.shape[0]
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or not 1 <= k <= MAX_TILES:
        raise ParameterError(f"tiles must be an integer within 1..{MAX_TILES}, got {k!r}")
    if not (isinstance(band, (int, float)) and math.isfinite(band) and 0 <= band <= 4):
        raise ParameterError(f"tile band must be within 0..4, got {band!r}")
    k = min(int(k), n)
    first = int(np.argmin(np.linalg.norm(x - x.mean(0), axis=1)))
    seeds = [first]
    dist = np.linalg.norm(x - x[first], axis=1)
    for _ in range(1, k):
        nxt = int(np.argmax(dist))
        seeds.append(nxt)
        dist = np.minimum(dist, np.linalg.norm(x - x[nxt], axis=1))
    c = x[seeds].copy()
    for _ in range(iters):
        lab = np.argmin(np.linalg.norm(x[:, None] - c[None], axis=2), axis=1)
        new = np.stack([x[lab == j].mean(0) if (lab == j).any() else c[j] for j in range(len(c))])
        if np.allclose(new, c, rtol=0, atol=1e-12):
            break
        c = new
    lab = np.argmin(np.linalg.norm(x[:, None] - c[None], axis=2), axis=1)
    c = c[np.unique(lab)]
    w = np.stack([blend_weights(c, p, band) for p in x])             # (N, k') weights at every camera
    return c, [np.flatnonzero(w[:, j] > 0).astype(np.int64) for j in range(len(c))]


def train_tiles(lf, cfg, opts, tiles: int, band: float = DEFAULT_BAND, progress=None) -> dict:
    """Train one LFN per region of camera space (:func:`partition_cameras`); every network gets
    ``opts`` (its steps, batch, …) and trains on the training views (``opts.holdout``'s split,
    the same for all tiles) that its region is blended at.

    Returns:
        {"centres": (K, 3), "band": band, "tiles": [(model, occ, info) per tile], "train_views",
        "test_views"} — info as :func:`lfn_stream.training.train` returns it.
    """
    from .training import split_views, train

    train_v, test_v = split_views(lf, opts.holdout)
    if opts.train_views is not None:
        train_v = np.asarray(opts.train_views, np.int64)
    pos = lf.positions.reshape(-1, 3)[train_v]
    centres, members = partition_cameras(pos, tiles, band)
    out = []
    for j, m in enumerate(members):
        ck = None if opts.checkpoint is None else f"{opts.checkpoint}.tile{j:02d}.npz"
        o = dataclasses.replace(opts, train_views=train_v[m].tolist(), history=[], checkpoint=ck)

        def prog(step, loss, j=j):
            if progress:
                progress(f"train tile {j + 1}/{len(members)}", step + 1, o.steps)

        model, occ, info = train(lf, cfg, o, progress=prog)
        info["test_views"] = test_v.tolist()
        out.append((model, occ, info))
    return {"centres": centres, "band": float(band), "tiles": out, "train_views": train_v.tolist(),
            "test_views": test_v.tolist()}


def tile_file_names(manifest: str | os.PathLike, count: int) -> list[str]:
    """Names of the submodel files written beside ``manifest`` (``STEM.tileNN.lfc``)."""
    stem = Path(manifest).name
    stem = stem[:-5] if stem.lower().endswith(".json") else stem
    return [f"{stem}.tile{j:02d}.lfc" for j in range(count)]


def manifest_of(centres: np.ndarray, band: float, files: list[str], views: list) -> dict:
    return {"format": FORMAT_ID, "version": FORMAT_VERSION, "band": float(band),
            "tiles": [{"file": f, "centre": [float(v) for v in c], "views": [int(x) for x in vs]}
                      for f, c, vs in zip(files, np.asarray(centres, np.float64), views)]}


def write_manifest(path: str | os.PathLike, manifest: dict) -> None:
    """Write the manifest atomically (temp file + rename)."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    try:
        tmp.write_text(json.dumps(manifest))
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def read_manifest(data: bytes, name: str) -> dict:
    """Parse and check a manifest (module docstring); FormatError naming ``name`` otherwise."""
    if len(data) > MAX_MANIFEST_BYTES:
        raise FormatError(f"{name}: a tile manifest is at most {MAX_MANIFEST_BYTES} bytes, this is {len(data)}")
    try:
        m = json.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError, RecursionError) as e:
        raise FormatError(f"{name}: not a tile manifest (JSON: {str(e)[:80]})") from None
    if not isinstance(m, dict) or m.get("format") != FORMAT_ID:
        raise FormatError(f"{name}: not a tile manifest (no \"format\": \"{FORMAT_ID}\")")
    if m.get("version") != FORMAT_VERSION:
        raise FormatError(f"{name}: tile manifest version {m.get('version')!r} is not supported (this reader: "
                          f"{FORMAT_VERSION})")
    band, tiles = m.get("band", DEFAULT_BAND), m.get("tiles")
    if isinstance(band, bool) or not isinstance(band, (int, float)) or not (math.isfinite(band) and 0 <= band <= 4):
        raise FormatError(f"{name}: band must be a number within 0..4, got {band!r}")
    if not isinstance(tiles, list) or not 1 <= len(tiles) <= MAX_TILES:
        raise FormatError(f"{name}: tiles must be a list of 1..{MAX_TILES} entries")
    files, centres = [], []
    for i, t in enumerate(tiles):
        f, c = (t.get("file"), t.get("centre")) if isinstance(t, dict) else (None, None)
        if not isinstance(f, str) or len(f) > 255 or not _NAME.match(f) or ".." in f.split("/"):
            raise FormatError(f"{name}: tile {i}: file must be a relative name beside the manifest (letters, digits, "
                              f"'._-/', no '..'), got {f!r}")
        if not (isinstance(c, list) and len(c) == 3 and all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                                            and math.isfinite(v) and abs(v) < 1e12 for v in c)):
            raise FormatError(f"{name}: tile {i}: centre must be 3 finite numbers, got {c!r}")
        files.append(f)
        centres.append([float(v) for v in c])
    return {"band": float(band), "files": files, "centres": np.asarray(centres, np.float64)}


def _resolve(base: str, name: str) -> str:
    from formats.remote import is_url

    if is_url(base):
        head, _, _ = base.rpartition("/")
        return f"{head}/{name}"
    return str(Path(base).parent / name)


class TiledLfnRenderer:
    """Renderer over a tile set: opens the manifest (path or URL), opens each submodel file on
    first use (a URL's by byte ranges; ``cache_bytes``, the page-cache budget of the whole set,
    is split evenly among the tiles' caches, at least 4 KiB each), and
    renders a camera by blending the submodels around it (module docstring). The pose methods
    and :meth:`render_pose` / :meth:`to_pixels` are those of :class:`LfnRenderer`, so renderers
    and the CLI use either.

    Attributes:
        centres: (K, 3) tile centres; band: the blend band; files: the submodels' locations.
        rays_evaluated: rays run through any submodel; tiles_rendered: submodel renders.
    """

    def __init__(self, source: str | os.PathLike, device: str | None = None, *, partial: bool = False,
                 cache_bytes: int | None = None, limits=None):
        from formats.remote import is_url, open_remote

        src = str(source)
        self.name = src
        if is_url(src):
            r = open_remote(src, cache_bytes=cache_bytes or (1 << 20))
            try:
                if r.size > MAX_MANIFEST_BYTES:
                    raise FormatError(f"{src}: a tile manifest is at most {MAX_MANIFEST_BYTES} bytes, this is {r.size}")
                data = bytes(r.read(0, r.size))
            finally:
                r.close()
        else:
            p = Path(src)
            if not p.is_file():
                raise ParameterError(f"{src}: no such tile manifest")
            if p.stat().st_size > MAX_MANIFEST_BYTES:
                raise FormatError(f"{src}: a tile manifest is at most {MAX_MANIFEST_BYTES} bytes")
            data = p.read_bytes()
        m = read_manifest(data, src)
        self.manifest_bytes = len(data)
        self.band, self.centres = m["band"], m["centres"]
        self.files = [_resolve(src, f) for f in m["files"]]
        per = None if cache_bytes is None else max(4096, int(cache_bytes) // len(self.files))
        self._kw = {"partial": partial, "cache_bytes": per, **({"limits": limits} if limits else {})}
        self._device = device
        self._tiles: dict[int, object] = {}
        self.tiles_rendered = 0
        first = self.tile(0)
        self.rows, self.cols = first.rows, first.cols
        self.height, self.width, self.channels, self.dtype = first.height, first.width, first.channels, first.dtype
        self.cfg = first.cfg

    def tile(self, j: int):
        """The submodel j's :class:`LfnRenderer` (opened on first use; checked against tile 0)."""
        from formats.lfcfile import open_lfc

        from .render import LfnRenderer

        if j not in self._tiles:
            f = open_lfc(self.files[j], **self._kw)
            try:
                if f.codec != "lfn":
                    raise FormatError(f"{self.files[j]}: a tile must be a light field network file, not {f.codec!r}")
                r = LfnRenderer(f, device=self._device)
            except LfcError:
                f.close()
                raise
            if self._tiles:
                ref = self._tiles[min(self._tiles)]
                if (r.rows, r.cols, r.height, r.width, r.channels, r.dtype) != \
                        (ref.rows, ref.cols, ref.height, ref.width, ref.channels, ref.dtype) or \
                        (r.cfg.min_neurons, r.cfg.max_neurons) != (ref.cfg.min_neurons, ref.cfg.max_neurons):
                    f.close()
                    raise FormatError(f"{self.files[j]}: tile {j}'s scene or network sizes differ from the others'")
            self._tiles[j] = r
        return self._tiles[j]

    # -- cameras: those of the capture (every tile file holds them; tile 0's are used) ----------
    def pose(self, row: int, col: int) -> np.ndarray:
        return self.tile(0).pose(row, col)

    def grid_pose(self, s: float, t: float) -> np.ndarray:
        return self.tile(0).grid_pose(s, t)

    def turn_pose(self, pose: np.ndarray, yaw: float, pitch: float = 0.0) -> np.ndarray:
        return self.tile(0).turn_pose(pose, yaw, pitch)

    def orbit_pose(self, row: int, col: int, yaw: float, pitch: float = 0.0) -> np.ndarray:
        return self.tile(0).orbit_pose(row, col, yaw, pitch)

    def stereo_poses(self, pose: np.ndarray, ipd: float):
        return self.tile(0).stereo_poses(pose, ipd)

    @property
    def poses(self) -> np.ndarray:
        return self.tile(0).poses

    # -- sizes: every tile has the same neuron range; each shows its own display ladder ---------
    @property
    def neurons(self) -> float:
        """The largest size every opened tile's bytes hold (tile 0 before others are opened)."""
        return min(t.neurons for t in self._tiles.values())

    @property
    def display_neurons(self) -> float:
        return min(t.display_neurons for t in self._tiles.values())

    def display_neurons_at(self, scale: float | None = None) -> float:
        """The smallest display size of the opened tiles at ``scale`` (LfnRenderer.display_neurons_at)."""
        return min(t.display_neurons_at(scale) for t in self._tiles.values())

    def neurons_at(self, level: float) -> float:
        return self.tile(0).neurons_at(level)

    @property
    def rays_evaluated(self) -> int:
        return sum(t.rays_evaluated for t in self._tiles.values())

    def weights(self, c2w) -> dict[int, float]:
        """{tile: weight} of the submodels a camera (4×4 camera-to-world) renders with."""
        from .render import LfnRenderer

        c2w = LfnRenderer._check_pose(c2w)
        w = blend_weights(self.centres, c2w[:3, 3], self.band)
        return {int(j): float(w[j]) for j in np.flatnonzero(w > 0)}

    def render_pose(self, c2w, neurons: float | None = None, scale: float | None = None) -> np.ndarray:
        """A view from any camera pose: the blend of the submodels around it (each at ``neurons``,
        default its own display size, and ``scale`` as :meth:`LfnRenderer.render_pose`).

        Returns:
            (h, w, 4) float32 RGBA (premultiplied) in [0, 1].
        """
        return self._blend(c2w, lambda t: t.render_pose(c2w, neurons, scale))

    def _blend(self, c2w, render) -> np.ndarray:
        """Σ weight · ``render(tile)`` (float32) over the submodels the camera blends (:meth:`weights`)."""
        out = None
        for j, wj in self.weights(c2w).items():
            img = render(self.tile(j))
            self.tiles_rendered += 1
            out = img * np.float32(wj) if out is None else out + img * np.float32(wj)
        return out

    def foveation_map(self, gaze: tuple[float, float], inner: float = 0.1, outer: float = 0.5, dither: bool = True,
                      sizes: int = 8, frame: int = 0, scale: float = 1.0) -> np.ndarray:
        """:meth:`LfnRenderer.foveation_map` over the sizes every opened tile holds (the tiles share
        their configuration; a prefix may hold fewer steps in one tile)."""
        return min(self._tiles.values(), key=lambda t: t.neurons).foveation_map(gaze, inner, outer, dither, sizes,
                                                                               frame, scale)

    def render_pose_lod_mip(self, c2w, lod: np.ndarray, max_level: int | None = None, blend: float | None = None,
                            bias: float = 0.0) -> np.ndarray:
        """A foveated view from any camera pose: the blend of the submodels' own
        :meth:`LfnRenderer.render_pose_lod_mip` frames of the size map ``lod`` (each tile's
        lattices, sizes and silhouettes; the weights of :meth:`render_pose`).

        Returns:
            (h, w, 4) float32 RGBA (premultiplied), (h, w) = ``lod``'s shape.
        """
        kw = {k: v for k, v in (("max_level", max_level), ("blend", blend)) if v is not None}
        return self._blend(c2w, lambda t: t.render_pose_lod_mip(c2w, lod, bias=bias, **kw))

    def render(self, row: int, col: int, neurons: float | None = None, scale: float | None = None) -> np.ndarray:
        """A captured camera (row, col) rendered by the blend (:meth:`render_pose`)."""
        return self.render_pose(self.pose(row, col), neurons, scale)

    def prefix_bytes(self, neurons: float) -> int:
        """Bytes every tile's file prefix holding a network of ``neurons`` needs, summed (what a
        session that visits every tile fetches at that size), plus the manifest's."""
        from .evaluate import prefix_bytes

        return self.manifest_bytes + sum(prefix_bytes(self.tile(j), neurons) for j in range(len(self.files)))

    def to_pixels(self, rgba: np.ndarray) -> np.ndarray:
        return self.tile(0).to_pixels(rgba)

    # -- decoding captured views (what ``lfcodec decode`` asks of a decoder) ----------------
    @property
    def levels(self) -> float:
        return self.tile(0).levels

    @property
    def scene(self) -> dict:
        """The capture's geometry (tile 0's file: every tile holds the whole capture's)."""
        return self.tile(0).file.scene

    def decode_view(self, row: int, col: int, level: float = 0) -> np.ndarray:
        """Full-size pixels of a captured view rendered by the blend, at a level (0 = the
        largest network every tile's bytes hold)."""
        return self.to_pixels(self.render(row, col, self.neurons_at(level), scale=1.0))

    #: whole views by flat index: the codec interface's own loop over :meth:`decode_view`
    decode_views = Decoder.decode_views

    def decode_block(self, *a, **k):
        raise UnsupportedError("block random access is an RLFC feature; a tile set of light field networks renders "
                               "rays (use --view)")

    def info(self) -> dict:
        return {"codec": "lfn", "tiles": len(self.files), "band": self.band,
                "summary": f"tile set of {len(self.files)} light field networks over camera space (blend band "
                           f"{self.band:g}); tile 0: {self.tile(0).info()['summary']}"}

    def close(self) -> None:
        for t in self._tiles.values():
            t.file.close()
        self._tiles.clear()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def open_tiles(source, device: str | None = None, **kw) -> TiledLfnRenderer:
    """Open a tile set's manifest (path or URL): :class:`TiledLfnRenderer`."""
    return TiledLfnRenderer(source, device, **kw)


__all__ = ["FORMAT_ID", "blend_weights", "partition_cameras", "train_tiles", "tile_file_names", "manifest_of",
           "write_manifest", "read_manifest", "TiledLfnRenderer", "open_tiles"]
