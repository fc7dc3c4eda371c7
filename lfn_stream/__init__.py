"""lfn_stream: light field networks with continuous levels of detail, streamed by network size.

Public API:
    LfnConfig, NestedLFN, OccupancyNet — the model
    TrainOptions, train — training on a LightField
    to_sections, LfnCodec — pack a trained network for an .lfc file; the codec plug-in
    first_prefix_bytes, auto_occupancy — the first renderable prefix a network shape makes, and
        the occupancy net size that keeps it within 8 KB
    LfnRenderer — render from a file or any prefix of it (fractional / per-pixel sizes)
    LfnStream — the same file read and checked without torch (what ``lfcodec info`` says)
    encode_tiles, open_tiles, TiledLfnRenderer — tile sets: one network per region of camera space

Names load on first use (PEP 562), so that ``import lfn_stream`` and the codec plug-in cost no
torch import until a network is built, trained or rendered (every ``lfcodec`` command loads
each codec to list its options).
"""
from __future__ import annotations

import importlib

#: public name → the submodule that defines it
_WHERE = {"LfnConfig": "config", "CODEC_ID": "config", "CODEC_VERSION": "config", "MOVED_KEYS": "config",
          "NestedLFN": "model", "OccupancyNet": "model", "TrainOptions": "training", "train": "training",
          "to_sections": "codec", "LfnCodec": "codec", "first_prefix_bytes": "codec",
          "auto_occupancy": "codec", "encode_tiles": "codec", "LfnRenderer": "render",
          "LfnStream": "stream", "TiledLfnRenderer": "tiles", "open_tiles": "tiles"}

__all__ = ["LfnConfig", "NestedLFN", "OccupancyNet", "TrainOptions", "train", "to_sections", "LfnRenderer", "LfnStream",
           "encode_tiles", "open_tiles", "TiledLfnRenderer", "LfnCodec", "first_prefix_bytes", "auto_occupancy",
           "CODEC_ID", "CODEC_VERSION", "MOVED_KEYS"]


def __getattr__(name: str):
    mod = _WHERE.get(name)
    if mod is None:
        raise AttributeError(f"module 'lfn_stream' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{mod}", __name__), name)
    globals()[name] = value          # later lookups skip this function
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))
