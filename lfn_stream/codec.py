"""LFN ↔ .lfc: config + sections for the container (the codec never opens files)."""
from __future__ import annotations

from .config import LfnConfig
from .model import NestedLFN, OccupancyNet
from .pack import pack_network, step_bytes
from .render import CODEC_ID, CODEC_VERSION


def to_sections(model: NestedLFN, occ: OccupancyNet | None, info: dict, dtype: str = "fp16"):
    """(config, sections) of a trained network for :func:`formats.lfcfile.write_lfc`."""
    cfg: LfnConfig = model.cfg
    sections = pack_network(model, occ, dtype)
    config = {"network": cfg.to_dict(), "norm": info["norm"], "weights": dtype, "train": {
        k: info[k] for k in ("train_views", "test_views", "steps", "train_s") if k in info},
        "step_bytes": [step_bytes(cfg, j, dtype) for j in (cfg.min_width, cfg.max_width - 1)]}
    return config, sections


__all__ = ["to_sections", "CODEC_ID", "CODEC_VERSION"]
