"""The lfcodec exception hierarchy.

Every error the library raises on bad input is an :class:`LfcError`; the CLI turns it into a
one-line message and exit code 2. Messages name the file, section or view and what was
expected.
"""
from __future__ import annotations


class LfcError(Exception):
    """Base class of every error lfcodec raises on bad input or bad files."""


class FormatError(LfcError):
    """A file is not a valid .lfc container (bad magic, bad table, bad offsets)."""


class ChecksumError(FormatError):
    """Stored data does not match its checksum (corruption or truncation)."""


class TruncatedError(FormatError):
    """A file or buffer ends before the data it declares."""


class UnsupportedError(LfcError):
    """A valid file or request that this version cannot handle (newer version, unknown codec)."""


class SceneError(LfcError):
    """A scene folder cannot be read as a light field (missing views, mixed sizes, ...)."""


class ParameterError(LfcError, ValueError):
    """A codec parameter or argument is out of its valid range."""


class WorkerError(LfcError):
    """A worker process died, or a cluster could not be reached (parallel encodes)."""
