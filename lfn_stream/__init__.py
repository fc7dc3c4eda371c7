"""lfn_stream: light field networks with continuous levels of detail, streamed by network size.

Public API:
    LfnConfig, NestedLFN, OccupancyNet — the model
    TrainOptions, train — training on a LightField
    to_sections, LfnCodec — pack a trained network for an .lfc file; the codec plug-in
    LfnRenderer — render from a file or any prefix of it (fractional / per-pixel sizes)
"""
from .codec import CODEC_ID, CODEC_VERSION, MOVED_KEYS, LfnCodec, to_sections
from .config import LfnConfig
from .model import NestedLFN, OccupancyNet
from .render import LfnRenderer
from .train import TrainOptions, train

__all__ = ["LfnConfig", "NestedLFN", "OccupancyNet", "TrainOptions", "train", "to_sections", "LfnRenderer",
           "LfnCodec", "CODEC_ID", "CODEC_VERSION", "MOVED_KEYS"]
