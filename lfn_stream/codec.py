"""LFN as an lfcodec codec plug-in (entry point ``lfn`` in the ``lfcodec.codecs`` group):
config + sections for the container (the codec never opens files). Importing it does not
import torch (the CLI loads every codec to list its options); the network's modules load
when a method first needs them."""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from formats.codec_api import Codec, EncodeOptions, Encoded, is_real
from formats.errors import ParameterError

from .config import CODEC_ID, CODEC_VERSION, MOVED_KEYS, LfnConfig

if TYPE_CHECKING:                      # (annotations only: these modules import torch)
    from .model import NestedLFN, OccupancyNet
    from .render import LfnRenderer


def to_sections(model: NestedLFN, occ: OccupancyNet | None, info: dict, dtype: str = "fp16"):
    """(config, sections) of a trained network for :func:`formats.lfcfile.write_lfc` (with
    ``more=MOVED_KEYS``: the cameras and evaluation lists go after the network)."""
    from .pack import step_bytes, stream_sections

    cfg: LfnConfig = model.cfg
    sections = stream_sections(model, occ, dtype)
    config = {"network": cfg.to_dict(), "norm": info["norm"], "weights": dtype, "train": {
        k: info[k] for k in ("train_views", "test_views", "steps") if k in info},
        "step_bytes": [step_bytes(cfg, j, dtype) for j in (cfg.min_neurons, cfg.max_neurons - 1)]}
    if info.get("display"):
        config["display"] = [int(w) for w in info["display"]]
    if info.get("display_scales"):
        config["display_scales"] = [[float(sc), [int(w) for w in lad]] for sc, lad in info["display_scales"]]
    return config, sections


def heldout_report(lf, config: dict, sections, info: dict) -> dict:
    """Held-out quality of a trained network as the file will hold it (fp16 weights included):
    the full network renders every held-out view at the scene's resolution, scored against the
    views (RGB premultiplied on black, plus alpha when present; :mod:`lfn_stream.evaluate`) beside
    the nearest training view (camera distance)."""
    from formats.lfcfile import lfc_bytes, open_lfc

    from .evaluate import evaluate
    from .render import LfnRenderer

    blob = lfc_bytes(CODEC_ID, CODEC_VERSION, config, lf.geometry(), sections, more=MOVED_KEYS)
    r = LfnRenderer(open_lfc(blob), device="cpu")
    row = evaluate(r, lf, info["test_views"], info["train_views"], [float(r.cfg.max_neurons)])[0]
    return {"heldout_views": len(info["test_views"]), "psnr_heldout": round(row["psnr"], 3),
            "ssim_heldout": None if row["ssim"] is None else round(row["ssim"], 4),
            "psnr_heldout_nearest_view": round(row["psnr_nearest_view"], 3)}


NET_KEYS = ("depth", "min_neurons", "max_neurons", "occupancy_neurons")
TRAIN_KEYS = ("steps", "batch", "lr", "holdout", "device", "checkpoint", "time_limit_s", "lod_levels")
OPTIONS = {"tiles": int, "tile_band": float, "depth": int, "min_neurons": int, "max_neurons": int,
           "occupancy_neurons": int, "steps": int, "batch": int, "lr": float, "holdout": int, "device": str,
           "checkpoint": str, "weights": str, "resolution": int, "lod_levels": int, "time_limit_s": float}


def _setup(lf, p: dict):
    """(full-size light field, the one trained on, LfnConfig, TrainOptions, weight dtype) from the
    codec's params (unknown keys are a ParameterError)."""
    import dataclasses

    from formats.transform import resize_lightfield

    from .training import TrainOptions

    if not isinstance(lf.views, np.ndarray):          # a ViewStack (zarr, dask, ...): read it all
        lf = dataclasses.replace(lf, views=np.asarray(lf.views))
    p = dict(p)
    for k, v in p.items():                            # types first (range tests meet a string untyped)
        typ = OPTIONS.get(k)
        if v is not None and (typ in (int, float) and not is_real(v) or typ is str and not isinstance(v, str)):
            raise ParameterError(f"--{k.replace('_', '-')} must be {'a number' if typ is not str else 'a string'}, "
                                 f"got {v!r}")
    if p.pop("tiles", 1) == 1 and "tile_band" in p:
        raise ParameterError("--tile-band sets how tiles blend: it goes with --tiles K (K > 1)")
    p.pop("tile_band", None)
    weights = p.pop("weights", "fp16")
    resolution = p.pop("resolution", 128)
    full = lf
    if resolution:   # train at reduced resolution; the file keeps the scene's geometry (renders full size)
        if resolution < 8:
            raise ParameterError(f"--resolution must be 0 (full) or >= 8 pixels, got {resolution}")
        lf = resize_lightfield(lf, resolution)
    if weights not in ("fp16", "fp32"):
        raise ParameterError(f"weights must be fp16 or fp32, got {weights!r}")
    unknown = set(p) - set(NET_KEYS) - set(TRAIN_KEYS)
    if unknown:
        raise ParameterError(f"unknown LFN option(s): {', '.join(sorted(unknown))}")
    cfg = LfnConfig(**{k: p[k] for k in NET_KEYS if k in p})
    if "occupancy_neurons" not in p and full.has_alpha:
        cfg = auto_occupancy(full, cfg, weights)
    opts = TrainOptions(**{k: p[k] for k in TRAIN_KEYS if k in p})
    return full, lf, cfg, opts, weights


#: issue 17's bound on the first renderable prefix (header, meta, base network, occupancy net)
FIRST_PREFIX_BYTES = 8192
#: the occupancy net's size where the default (32) would pass that bound: 802 B of fp16 weights
#: instead of 2 626, the same held-out quality, ~10% more render time (BENCHMARKS.md)
SMALL_OCCUPANCY = 16


def first_prefix_bytes(lf, cfg: LfnConfig, weights: str = "fp16") -> int:
    """Bytes of the first renderable prefix of a network ``cfg`` trained on ``lf`` (the file
    up to the end of its occupancy net, else of its base network), measured on an untrained
    network packed with this scene's geometry and display ladders as long as trained ones (20
    sizes at each of four display scales); the weights' values do not change their size."""
    import torch

    from formats.container import Container
    from formats.lfcfile import lfc_bytes

    from .evaluate import first_renderable_end
    from .model import NestedLFN, OccupancyNet

    with torch.random.fork_rng():
        torch.manual_seed(0)
        model = NestedLFN(cfg)
        occ = OccupancyNet(cfg.occupancy_neurons, cfg.in_features) if cfg.occupancy_neurons else None
    lo, hi = cfg.min_neurons, cfg.max_neurons
    lad = sorted({int(round(lo + (hi - 1 - lo) * i / 19)) for i in range(20)})
    n = lf.rows * lf.cols
    info = {"norm": {"centre": [0.0, 0.0, 0.0], "radius": 1.0}, "train_views": list(range(n)), "test_views": [],
            "display": lad + ([hi] if lad[-1] < hi else []),
            "display_scales": [[s, lad] for s in (0.125, 0.25, 0.5, 1.0)]}
    config, sections = to_sections(model, occ, info, weights)
    return first_renderable_end(Container(lfc_bytes(CODEC_ID, CODEC_VERSION, config, lf.geometry(), sections,
                                                    more=MOVED_KEYS)))


def auto_occupancy(lf, cfg: LfnConfig, weights: str = "fp16") -> LfnConfig:
    """``cfg`` with the default occupancy net (32 neurons), or a 16-neuron one where 32 would put
    the first renderable prefix over :data:`FIRST_PREFIX_BYTES` (deep or wide base networks:
    depth 8 × 16 neurons is 9.5 KB with 32, 7.7 KB with 16) and 16 keeps it under."""
    import dataclasses

    if cfg.occupancy_neurons <= SMALL_OCCUPANCY or first_prefix_bytes(lf, cfg, weights) <= FIRST_PREFIX_BYTES:
        return cfg
    small = dataclasses.replace(cfg, occupancy_neurons=SMALL_OCCUPANCY)
    return small if first_prefix_bytes(lf, small, weights) <= FIRST_PREFIX_BYTES else cfg


def finish_network(full, lf, model, occ, info: dict, opts, weights: str, progress=None):
    """(config, sections, summary) of a trained network: its display ladders (measured on training
    views at four display scales: held-out views stay unseen), packed, and scored on the held-out
    views at full size."""
    if progress:
        progress("display ladder", 0, 1)
    # measured on training views rendered at each display scale: held-out views stay unseen for
    # evaluation (BENCHMARKS.md, "display ladders per scale")
    from .evaluate import measure_display_ladders

    # on the training device (every size of the network on ~80 000 pixels: seconds on a CPU for
    # a large network, milliseconds on a GPU)
    # (scales of the file's views: a network trained at reduced resolution renders them larger)
    info["display"], info["display_scales"] = measure_display_ladders(model, lf, info["train_views"], info["norm"],
                                                                      opts.device, view_scale=lf.width / full.width)
    config, sections = to_sections(model, occ, info, weights)
    summary = {"steps": info["steps"], "train_s": round(info["train_s"], 1), "params": model.n_params(),
               "display_sizes": len(info["display"]),
               "final_loss": opts.history[-1][1] if opts.history else None}
    if info["test_views"]:
        if progress:
            progress("held-out views", 0, len(info["test_views"]))
        summary.update(heldout_report(full, config, sections, info))
    return config, sections, summary


def encode_tiles(lf, options: EncodeOptions, out, progress=None) -> dict:
    """Train a tile set (:mod:`lfn_stream.tiles`: one LFN per region of camera space, ``tiles``
    and ``tile_band`` in ``options.params``) and write it: ``out`` (a ``.json`` manifest) and one
    ``.lfc`` per tile beside it (each written atomically, the manifest last). Returns a report:
    bytes, per-tile summaries, and the blended renderer's held-out PSNR beside the nearest
    training view's."""
    from pathlib import Path

    from formats.lfcfile import write_lfc

    from .tiles import DEFAULT_BAND, MAX_TILES, manifest_of, open_tiles, tile_file_names, train_tiles, write_manifest

    if options.target_psnr is not None or options.target_bpp is not None or options.lossless:
        raise ParameterError("light field networks take no --target-psnr/--target-bpp/--lossless "
                             "(train longer or larger instead)")
    out = Path(out)
    if out.suffix.lower() != ".json":
        raise ParameterError(f"{out}: a tile set is written as a manifest named *.json (and one .lfc per tile "
                             f"beside it)")
    p = dict(options.params)
    k, band = p.get("tiles", 1), p.get("tile_band", DEFAULT_BAND)
    full, small, cfg, opts, weights = _setup(lf, p)
    inputs = {Path(x).resolve() for x in lf.meta.get("input_paths", ())}
    for n in tile_file_names(out, k if isinstance(k, int) and 0 < k <= MAX_TILES else 0):   # (k: checked below)
        if (out.parent / n).resolve() in inputs:
            raise ParameterError(f"{out.parent / n}: refusing to write over one of the input files of the scene")
    res = train_tiles(small, cfg, opts, k, band, progress)
    names = tile_file_names(out, len(res["tiles"]))
    total, tiles = 0, []
    for j, ((model, occ, info), name) in enumerate(zip(res["tiles"], names)):
        info_t = {**info, "test_views": []}            # scored below as a blend, not tile by tile
        config, sections, summary = finish_network(full, small, model, occ, info_t, opts, weights, progress)
        config["tile"] = {"index": j, "count": len(names), "centre": [float(v) for v in res["centres"][j]]}
        nbytes = write_lfc(out.parent / name, CODEC_ID, CODEC_VERSION, config, full.geometry(), sections,
                           more=MOVED_KEYS)
        total += nbytes
        tiles.append({"file": name, "bytes": nbytes, "train_views": len(info["train_views"]), **summary})
    manifest = manifest_of(res["centres"], res["band"], names, [t[2]["train_views"] for t in res["tiles"]])
    write_manifest(out, manifest)
    total += out.stat().st_size
    report = {"files": [out.name, *names], "tiles": tiles, "bytes": total, "band": res["band"]}
    if res["test_views"]:
        from .evaluate import evaluate

        if progress:
            progress("held-out views", 0, len(res["test_views"]))
        with open_tiles(out, device="cpu") as r:
            row = evaluate(r, full, res["test_views"], np.asarray(res["train_views"]), [float(cfg.max_neurons)])[0]
        report.update({"heldout_views": len(res["test_views"]), "psnr_heldout": round(row["psnr"], 3),
                       "ssim_heldout": None if row["ssim"] is None else round(row["ssim"], 4),
                       "psnr_heldout_nearest_view": round(row["psnr_nearest_view"], 3)})
    return report


class LfnCodec(Codec):
    codec_id = CODEC_ID
    version = CODEC_VERSION
    description = "light field network with continuous levels of detail, streamed by network size"

    def encode(self, lf, options: EncodeOptions, progress=None) -> Encoded:
        from .training import train

        if options.target_psnr is not None or options.target_bpp is not None or options.lossless:
            raise ParameterError("light field networks take no --target-psnr/--target-bpp/--lossless "
                                 "(train longer or larger instead)")
        p = dict(options.params)
        if p.get("tiles", 1) != 1:
            raise ParameterError("--tiles writes a tile set (a manifest and one file per tile): use `lfcodec train "
                                 "SCENE OUT.json --tiles K` (or lfn_stream.codec.encode_tiles)")
        full, lf, cfg, opts, weights = _setup(lf, p)

        def prog(step, loss):
            if progress:
                progress("train", step + 1, opts.steps)

        model, occ, info = train(lf, cfg, opts, progress=prog)
        config, sections, summary = finish_network(full, lf, model, occ, info, opts, weights, progress)
        notes = []
        if summary.get("psnr_heldout", np.inf) < summary.get("psnr_heldout_nearest_view", -np.inf):
            notes.append(f"held-out views: the network ({summary['psnr_heldout']:.2f} dB) is below the nearest "
                         f"training view ({summary['psnr_heldout_nearest_view']:.2f} dB); train longer (--steps) "
                         f"or larger (--max-neurons)")
        return Encoded(config, sections, None, notes=notes, summary=summary, more=MOVED_KEYS)

    def open(self, f, **kw) -> LfnRenderer:
        from .render import LfnRenderer

        return LfnRenderer(f, **kw)

    def describe(self, f) -> dict:
        """The file read and checked as a renderer would (weights included), without torch:
        :class:`~lfn_stream.stream.LfnStream`."""
        from .stream import LfnStream

        return LfnStream(f).info()

    set_suffix = ".json"      # a tile set's manifest (lfn_stream.tiles)

    def writes_set(self, options: EncodeOptions) -> bool:
        return options.params.get("tiles", 1) != 1

    def encode_set(self, lf, options: EncodeOptions, out, progress=None) -> dict:
        return encode_tiles(lf, options, out, progress)

    def open_set(self, source, **kw):
        from .tiles import open_tiles

        return open_tiles(source, **kw)

    def add_arguments(self, g) -> None:
        g.add_argument("--depth", type=int, default=None, help="lfn: hidden layers (default 6)")
        g.add_argument("--min-neurons", type=int, default=None, help="lfn: neurons per layer of the base network "
                                                                       "(default 16)")
        g.add_argument("--max-neurons", type=int, default=None, help="lfn: neurons per layer of the full network "
                                                                       "(default 128)")
        g.add_argument("--occupancy-neurons", type=int, default=None,
                       help="lfn: occupancy net size, used when the scene has alpha (default 32, or 16 where 32 "
                            "would put the first renderable prefix over 8 KB; 0 = none)")
        g.add_argument("--steps", type=int, default=None, help="lfn: optimizer steps (default 2000)")
        g.add_argument("--time-limit", dest="time_limit_s", type=float, default=None, metavar="SECONDS",
                       help="lfn: stop training after this many seconds (the learning-rate schedule then runs "
                            "over that time; --steps still caps the steps)")
        g.add_argument("--batch", type=int, default=None, help="lfn: rays per step (default 4096)")
        g.add_argument("--lr", type=float, default=None, help="lfn: Adam learning rate (default 0.003)")
        g.add_argument("--lod-levels", type=int, default=None,
                       help="lfn: levels trained per step, one from each slice of the width range (default 8; "
                            "1 = one random level)")
        g.add_argument("--resolution", type=int, default=None,
                       help="lfn: train at this many pixels on the long side (default 128; 0 = full)")
        g.add_argument("--holdout", type=int, default=None, help="lfn: hold out every k-th view (default 4; 0 = none)")
        g.add_argument("--device", default=None, help="lfn: cpu or cuda (default cpu)")
        g.add_argument("--weights", default=None, choices=["fp16", "fp32"], help="lfn: stored weight precision")
        g.add_argument("--checkpoint", default=None, help="lfn: checkpoint .npz (saved periodically; resumed from)")
        g.add_argument("--tiles", type=int, default=None,
                       help="lfn: train a tile set of this many networks over camera space (k-means of the camera "
                            "centres), written as OUT.json and one .lfc per tile beside it (default 1: one network)")
        g.add_argument("--tile-band", type=float, default=None,
                       help="lfn: tiles blend where a camera is within (1 + band) x its distance to the nearest tile "
                            "centre; each tile trains on the cameras it blends at (default 0.5)")

    def params_from_args(self, a) -> dict:
        return {k: getattr(a, k) for k in OPTIONS if getattr(a, k, None) is not None}


__all__ = ["to_sections", "heldout_report", "first_prefix_bytes", "auto_occupancy", "LfnCodec", "CODEC_ID", "CODEC_VERSION",
           "MOVED_KEYS"]
