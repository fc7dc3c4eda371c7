"""lfn_stream: light field networks with continuous levels of detail, streamed by network size.

Public API:
    LfnConfig, NestedLFN, OccupancyNet — the model
    TrainOptions, train — training on a LightField
    to_sections, LfnCodec — pack a trained network for an .lfc file; the codec plug-in
    LfnRenderer — render from a file or any prefix of it (fractional / per-pixel sizes)
    encode_tiles, open_tiles, TiledLfnRenderer — tile sets: one network per region of camera space
"""
from .codec import CODEC_ID, CODEC_VERSION, MOVED_KEYS, LfnCodec, encode_tiles, to_sections
from .config import LfnConfig
from .model import NestedLFN, OccupancyNet
from .render import LfnRenderer
from .tiles import TiledLfnRenderer, open_tiles
from .train import TrainOptions, train

__all__ = ["LfnConfig", "NestedLFN", "OccupancyNet", "TrainOptions", "train", "to_sections", "LfnRenderer",
           "encode_tiles", "open_tiles", "TiledLfnRenderer", "LfnCodec", "CODEC_ID", "CODEC_VERSION", "MOVED_KEYS"]
