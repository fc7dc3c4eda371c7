"""LFN as an lfcodec codec plug-in (entry point ``lfn`` in the ``lfcodec.codecs`` group):
config + sections for the container (the codec never opens files)."""
from __future__ import annotations

from formats.codec_api import Codec, EncodeOptions, Encoded
from formats.errors import ParameterError

from .config import LfnConfig
from .evaluate import display_ladder, sample_rays, size_psnr
from .model import NestedLFN, OccupancyNet
from .pack import step_bytes, stream_sections
from .render import CODEC_ID, CODEC_VERSION, MOVED_KEYS, LfnRenderer


def to_sections(model: NestedLFN, occ: OccupancyNet | None, info: dict, dtype: str = "fp16"):
    """(config, sections) of a trained network for :func:`formats.lfcfile.write_lfc` (with
    ``more=MOVED_KEYS``: the cameras and evaluation lists go after the network)."""
    cfg: LfnConfig = model.cfg
    sections = stream_sections(model, occ, dtype)
    config = {"network": cfg.to_dict(), "norm": info["norm"], "weights": dtype, "train": {
        k: info[k] for k in ("train_views", "test_views", "steps", "train_s") if k in info},
        "step_bytes": [step_bytes(cfg, j, dtype) for j in (cfg.min_neurons, cfg.max_neurons - 1)]}
    if info.get("display"):
        config["display"] = [int(w) for w in info["display"]]
    return config, sections


def heldout_report(lf, config: dict, sections, info: dict) -> dict:
    """Held-out quality of a trained network as the file will hold it (fp16 weights included):
    the full network renders every held-out view at the scene's resolution, scored against the
    views (RGB premultiplied on black, plus alpha when present; :mod:`lfn_stream.evaluate`) beside
    the nearest training view (camera distance)."""
    from formats.lfcfile import lfc_bytes, open_lfc

    from .evaluate import evaluate

    blob = lfc_bytes(CODEC_ID, CODEC_VERSION, config, lf.geometry(), sections, more=MOVED_KEYS)
    r = LfnRenderer(open_lfc(blob), device="cpu")
    row = evaluate(r, lf, info["test_views"], info["train_views"], [float(r.cfg.max_neurons)])[0]
    return {"heldout_views": len(info["test_views"]), "psnr_heldout": round(row["psnr"], 3),
            "ssim_heldout": None if row["ssim"] is None else round(row["ssim"], 4),
            "psnr_heldout_nearest_view": round(row["psnr_nearest_view"], 3)}


NET_KEYS = ("depth", "min_neurons", "max_neurons", "occupancy_neurons")
TRAIN_KEYS = ("steps", "batch", "lr", "holdout", "device", "checkpoint", "time_limit_s", "lod_levels")
OPTIONS = {"depth": int, "min_neurons": int, "max_neurons": int, "occupancy_neurons": int, "steps": int,
           "batch": int, "lr": float, "holdout": int, "device": str, "checkpoint": str, "weights": str,
           "resolution": int, "lod_levels": int}


class LfnCodec(Codec):
    codec_id = CODEC_ID
    version = CODEC_VERSION
    description = "light field network with continuous levels of detail, streamed by network size"

    def encode(self, lf, options: EncodeOptions, progress=None) -> Encoded:
        from .train import TrainOptions, train

        if options.target_psnr is not None or options.target_bpp is not None or options.lossless:
            raise ParameterError("light field networks take no --target-psnr/--target-bpp/--lossless "
                                 "(train longer or larger instead)")
        import dataclasses

        import numpy as np

        if not isinstance(lf.views, np.ndarray):          # a ViewStack (zarr, dask, ...): read it all
            lf = dataclasses.replace(lf, views=np.asarray(lf.views))
        from formats.transform import resize_lightfield

        p = dict(options.params)
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
        opts = TrainOptions(**{k: p[k] for k in TRAIN_KEYS if k in p})

        def prog(step, loss):
            if progress:
                progress("train", step + 1, opts.steps)

        model, occ, info = train(lf, cfg, opts, progress=prog)
        if progress:
            progress("display ladder", 0, 1)
        # measured on training rays: held-out views stay unseen for evaluation (measuring on half of them
        # instead gave no fewer drops on the other half; BENCHMARKS.md)
        rays, targets = sample_rays(lf, info["train_views"], info["norm"], seed=opts.seed)
        info["display"] = display_ladder(size_psnr(model, rays, targets, cfg), cfg)
        config, sections = to_sections(model, occ, info, weights)
        summary = {"steps": info["steps"], "train_s": round(info["train_s"], 1), "params": model.n_params(),
                   "display_sizes": len(info["display"]),
                   "final_loss": opts.history[-1][1] if opts.history else None}
        if info["test_views"]:
            if progress:
                progress("held-out views", 0, len(info["test_views"]))
            summary.update(heldout_report(full, config, sections, info))
        notes = []
        if summary.get("psnr_heldout", np.inf) < summary.get("psnr_heldout_nearest_view", -np.inf):
            notes.append(f"held-out views: the network ({summary['psnr_heldout']:.2f} dB) is below the nearest "
                         f"training view ({summary['psnr_heldout_nearest_view']:.2f} dB); train longer (--steps) "
                         f"or larger (--max-neurons)")
        return Encoded(config, sections, None, notes=notes, summary=summary, more=MOVED_KEYS)

    def open(self, f, **kw) -> LfnRenderer:
        return LfnRenderer(f, **kw)

    def add_arguments(self, g) -> None:
        g.add_argument("--depth", type=int, default=None, help="lfn: hidden layers (default 6)")
        g.add_argument("--min-neurons", type=int, default=None, help="lfn: neurons per layer of the base network "
                                                                       "(default 16)")
        g.add_argument("--max-neurons", type=int, default=None, help="lfn: neurons per layer of the full network "
                                                                       "(default 128)")
        g.add_argument("--occupancy-neurons", type=int, default=None,
                       help="lfn: occupancy net size, used when the scene has alpha (default 32; 0 = none)")
        g.add_argument("--steps", type=int, default=None, help="lfn: optimizer steps (default 2000)")
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

    def params_from_args(self, a) -> dict:
        return {k: getattr(a, k) for k in OPTIONS if getattr(a, k, None) is not None}


__all__ = ["to_sections", "heldout_report", "LfnCodec", "CODEC_ID", "CODEC_VERSION", "MOVED_KEYS"]
