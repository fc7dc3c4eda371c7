"""lfcodec's formats package: the .lfc container, scene readers/writers, pixel conventions,
metrics, the codec interface and registry, and the CLI. It imports no codec.

Public API:
    LightField, read_scene, write_views, plucker_rays — scenes
    estimate_warps, rectify_views, rectify_grid — a grid whose cameras are not rectified, rectified
    Container, ByteRangeSource, write_container — the raw container
    open_lfc, write_lfc, LfcFile — .lfc files with metadata
    Codec, Decoder, EncodeOptions, Encoded — the codec interface
    get_codec, open_decoder, available_codecs, register_codec — codecs by id
    LfcError and subclasses — errors
"""
__version__ = "0.2.0"

from .codec_api import Codec, Decoder, EncodeOptions, Encoded
from .container import ByteRangeSource, Container, SectionInfo, write_container
from .errors import (ChecksumError, FormatError, LfcError, ParameterError, SceneError, TruncatedError,
                     UnsupportedError)
from .lfcfile import LfcFile, open_lfc, write_lfc
from .lightfield import LightField
from .registry import available_codecs, get_codec, open_decoder, register_codec
from .parallel import WorkerError, make_runner
from .rectify import estimate_warps, rectify_grid, rectify_views
from .scenes import plucker_rays, read_scene, write_views
from .viewstack import ViewStack, from_array

__all__ = ["__version__", "ByteRangeSource", "Container", "SectionInfo", "write_container", "ChecksumError",
           "FormatError", "LfcError", "ParameterError", "SceneError", "TruncatedError", "UnsupportedError",
           "LfcFile", "open_lfc", "write_lfc", "LightField", "plucker_rays", "read_scene", "write_views",
           "Codec", "Decoder", "EncodeOptions", "Encoded", "available_codecs", "get_codec", "open_decoder",
           "register_codec", "WorkerError", "make_runner", "ViewStack", "from_array", "estimate_warps", "rectify_grid",
           "rectify_views"]
