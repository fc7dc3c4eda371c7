"""RLFC: random-access light field compression with key views
(after Pratapa & Manocha, I3D 2019), with profiles as plug-ins.

Public API:
    RlfcCodec — the codec plug-in (``formats.registry.get_codec("rlfc")``)
    encode(lf, options | **params) → formats.codec_api.Encoded
    encode_with_params(lf, RlfcParams) → (config, sections, loop): bise/dcp without rate control
    RlfcDecoder(lfc_file) — full / view / block / batched / progressive decoders
    RlfcParams — parameters of the BISE-family profiles (bise, dcp)
    get_profile, available_profiles — RLFC profiles by on-wire id
    bise — ASTC-conformant bounded integer sequence encoding
"""
from . import bise
from .codec import RlfcCodec, encode
from .decoder import RlfcDecoder
from .header import CODEC_ID, CODEC_VERSION
from .params import RlfcParams
from .profiles import available_profiles, get_profile
from .profiles.keyfamily import encode_with_params

__all__ = ["bise", "RlfcCodec", "encode", "RlfcDecoder", "RlfcParams", "get_profile", "available_profiles", "encode_with_params",
           "CODEC_ID", "CODEC_VERSION"]
