"""lfcodec's formats package: the .lfc container, scene readers/writers, metrics and the CLI.

Public API:
    LightField, read_scene, write_views, plucker_rays — scenes
    Container, ByteRangeSource, write_container — the raw container
    open_lfc, write_lfc, LfcFile — .lfc files with metadata
    LfcError and subclasses — errors
"""
__version__ = "0.1.0"

from .container import ByteRangeSource, Container, SectionInfo, write_container
from .errors import (ChecksumError, FormatError, LfcError, ParameterError, SceneError, TruncatedError,
                     UnsupportedError)
from .lfcfile import LfcFile, open_lfc, write_lfc
from .lightfield import LightField
from .scenes import plucker_rays, read_scene, write_views

__all__ = ["__version__", "ByteRangeSource", "Container", "SectionInfo", "write_container", "ChecksumError",
           "FormatError", "LfcError", "ParameterError", "SceneError", "TruncatedError", "UnsupportedError",
           "LfcFile", "open_lfc", "write_lfc", "LightField", "plucker_rays", "read_scene", "write_views"]
