"""lfn_stream: light field networks with continuous levels of detail, streamed by width.

Public API:
    LfnConfig, NestedLFN, OccupancyNet — the model
    TrainOptions, train — training on a LightField
    to_sections — pack a trained network for an .lfc file
    LfnRenderer — render from a file or any prefix of it (fractional / per-pixel levels)
"""
from .codec import CODEC_ID, CODEC_VERSION, to_sections
from .config import LfnConfig
from .model import NestedLFN, OccupancyNet
from .render import LfnRenderer
from .train import TrainOptions, train

__all__ = ["LfnConfig", "NestedLFN", "OccupancyNet", "TrainOptions", "train", "to_sections", "LfnRenderer",
           "CODEC_ID", "CODEC_VERSION"]
