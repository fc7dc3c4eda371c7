"""Codec registry: codec id in a file's metadata → the package that decodes it.

The container and scene modules never import a codec; only this registry (used by the CLI
and by ``open_decoder``) does, lazily.
"""
from __future__ import annotations

import importlib

from .errors import UnsupportedError
from .lfcfile import LfcFile

DECODERS = {"rlfc": ("rlfc.decoder", "RlfcDecoder"), "lfn": ("lfn_stream.render", "LfnRenderer")}


def open_decoder(f: LfcFile):
    """A decoder object for an opened file, chosen by its codec id."""
    try:
        mod, cls = DECODERS[f.codec]
    except KeyError:
        raise UnsupportedError(f"{f.container.name}: codec {f.codec!r} is not supported by this lfcodec "
                               f"(known: {', '.join(DECODERS)})") from None
    return getattr(importlib.import_module(mod), cls)(f)
