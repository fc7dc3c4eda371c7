"""RLFC: random-access light field compression with key views and BISE
(after Pratapa & Manocha, I3D 2019).

Public API:
    RlfcParams — encoder parameters
    encode_lightfield(lf, params) -> (config, sections, loop) ; Encoder for repeated encodes
    RlfcDecoder(lfc_file) — full / view / block / batched / progressive decoders
    bise — ASTC-conformant bounded integer sequence encoding
"""
from . import bise
from .decoder import RlfcDecoder
from .encoder import CODEC_ID, CODEC_VERSION, Encoder
from .encoder import encode as encode_lightfield
from .params import RlfcParams

__all__ = ["bise", "RlfcDecoder", "Encoder", "encode_lightfield", "RlfcParams", "CODEC_ID", "CODEC_VERSION"]
