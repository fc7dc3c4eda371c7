"""The one interface every codec implements, and the vocabulary it speaks.

A codec turns a :class:`~formats.lightfield.LightField` into a JSON-able config plus named
byte sections (``encode``), and opens a written file into a :class:`Decoder` (``open``). It
never opens files itself and never imports another codec; the container never imports a
codec. Codecs are found by their on-wire id through :mod:`formats.registry`.

Vocabulary (the same in every codec, the CLI and the docs):
    rows, cols: the view grid (unordered captures are 1 × N); view index = row·cols + col.
    height, width: a view's size in pixels (H × W everywhere, never W × H).
    channels: 1 grey, 2 grey + alpha, 3 RGB, 4 RGBA; dtype: uint8 or uint16 samples.
    level: 0 = full quality; larger = coarser, up to ``levels`` (the coarsest). Fractional
        levels where a codec supports them (networks).
    block: a B × B pixel tile of one view, the random-access unit (codecs that have one).
"""
from __future__ import annotations

import abc
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from .errors import ParameterError, UnsupportedError


@dataclass(frozen=True)
class EncodeOptions:
    """What a user asks of an encode, in codec-independent words.

    Attributes:
        target_psnr: colour PSNR floor in dB (pooled over all views), or None.
        target_bpp: whole-file bits-per-pixel ceiling, or None.
        min_view_psnr: per-view colour PSNR floor in dB, or None.
        lossless: bit-exact decode.
        profile: a codec's variant ("auto" lets the codec pick).
        params: codec-specific options (the codec validates them).
        workers: local worker processes for the codec's independent tasks (1 = this process).
        scheduler: a dask.distributed scheduler address (``tcp://host:8786``) or Client to run
            them on instead (:mod:`formats.parallel`). Neither changes the file written.
        keep_decoded: return the decoded views with the encode (:attr:`Encoded.decoded`). False
            lets a codec that would hold them for that (``rlfc`` ``tx``: one copy of the light
            field) not hold them; ``decoded`` is then None (decode the file to measure it).
            The file written is the same.
    """

    target_psnr: float | None = None
    target_bpp: float | None = None
    min_view_psnr: float | None = None
    lossless: bool = False
    profile: str = "auto"
    params: dict = field(default_factory=dict)
    workers: int = 1
    scheduler: object = None
    keep_decoded: bool = True

    def __post_init__(self):
        """Types only (a codec checks ranges): a string target compared with numbers deep in an
        encode was a TypeError."""
        for k in ("target_psnr", "target_bpp", "min_view_psnr"):
            v = getattr(self, k)
            if v is not None and not is_real(v):
                raise ParameterError(f"{k} must be a number or None, got {v!r}")
        for k in ("lossless", "keep_decoded"):
            if not isinstance(getattr(self, k), bool):
                raise ParameterError(f"{k} must be true or false, got {getattr(self, k)!r}")
        if not isinstance(self.profile, str):
            raise ParameterError(f"profile must be a name, got {self.profile!r}")
        if not isinstance(self.params, dict):
            raise ParameterError(f"params must be a dict of codec options, got {type(self.params).__name__}")


@dataclass
class Encoded:
    """An encoded light field, ready for :func:`formats.lfcfile.write_lfc`.

    Attributes:
        config: the codec's JSON-able config (stored in the file's metadata).
        sections: (name, bytes) in file order.
        decoded: (R, C, H, W, Ch) the pixels a decoder of the file returns at level 0 (the
            encoder's closed loop), or None when the codec cannot say without decoding.
        trace: the rate search's steps (JSON-able dicts), if any.
        notes: one-line warnings for the user (e.g. a target that was not met and why).
        target_met: whether every requested target was reached (None: no target).
        summary: JSON-able facts for reports (profile, chosen parameters, ...).
        more: metadata keys ("scene.KEY", "config.KEY") to store after the sections, in
            ``meta.more`` (:func:`formats.lfcfile.split_meta`), not in ``meta``.
    """

    config: dict
    sections: list
    decoded: np.ndarray | None = None
    trace: list = field(default_factory=list)
    notes: list = field(default_factory=list)
    target_met: bool | None = None
    summary: dict = field(default_factory=dict)
    more: tuple = ()


Progress = Callable[[str, int, int | None], None]
"""progress(stage, done, total): a stage name and a counter (total None when unknown)."""


def check_integers(**kw) -> None:
    """A ParameterError for any keyword argument that is not an integer (bools and floats
    included: a float index would pick a view or block silently)."""
    for k, x in kw.items():
        if isinstance(x, bool) or not isinstance(x, (int, np.integer)):
            raise ParameterError(f"{k} must be an integer, got {x!r}")


def is_real(x) -> bool:
    """A real number: a Python or numpy int or float, not a bool, a string or an array."""
    return isinstance(x, (int, float, np.integer, np.floating)) and not isinstance(x, bool)


def check_numbers(**kw) -> None:
    """A ParameterError for any keyword argument that is not a finite real number."""
    for k, x in kw.items():
        if not is_real(x) or not np.isfinite(x):
            raise ParameterError(f"{k} must be a finite number, got {x!r}")


def check_field_types(obj) -> None:
    """A ParameterError for any field of dataclass ``obj`` annotated ``int``, ``float``, ``bool``
    or ``str`` (optionally ``| None``) whose value is not of that kind. int and float fields take
    any real number (integrality and ranges are the caller's checks): what this catches is a
    string, a list or None where a number was meant, which range tests would meet untyped."""
    import dataclasses

    want = {"int": (is_real, "a number"), "float": (is_real, "a number"),
            "bool": (lambda v: isinstance(v, (bool, np.bool_)), "true or false"),
            "str": (lambda v: isinstance(v, str), "a string")}
    for f in dataclasses.fields(obj):
        ann = (f.type if isinstance(f.type, str) else getattr(f.type, "__name__", "")).replace(" ", "")
        optional = ann.endswith("|None")
        test, what = want.get(ann[:-5] if optional else ann, (None, None))
        v = getattr(obj, f.name)
        if test is not None and not (optional and v is None) and not test(v):
            raise ParameterError(f"{f.name} must be {what}{' or None' if optional else ''}, got {v!r}")


def check_view_indices(views, n: int) -> np.ndarray:
    """Flat view indices (any integer array-like) as int64, each within 0..n-1."""
    a = np.asarray(views)
    if a.dtype == bool or not (a.dtype.kind in "iu" or a.size == 0):
        raise ParameterError(f"view indices must be integers, got {a.dtype} values")
    a = a.astype(np.int64).ravel()
    if a.size and (a.min() < 0 or a.max() >= n):
        raise ParameterError(f"view index out of range (0..{n - 1})")
    return a


class Decoder(abc.ABC):
    """An opened file of one codec. Geometry attributes: rows, cols, height, width, channels,
    dtype (numpy), levels (int: valid levels are 0..levels)."""

    rows: int
    cols: int
    height: int
    width: int
    channels: int
    dtype: np.dtype
    levels: int

    @abc.abstractmethod
    def decode_view(self, row: int, col: int, level: float = 0) -> np.ndarray:
        """One view: (H, W, C) pixels."""

    def decode_views(self, views, level: float = 0) -> np.ndarray:
        """Whole views by flat index (row · cols + col): (n, H, W, C) pixels (a codec that
        decodes several views together overrides this)."""
        views = check_view_indices(views, self.rows * self.cols)
        if views.size == 0:
            return np.zeros((0, self.height, self.width, self.channels), self.dtype)
        return np.stack([self.decode_view(*divmod(int(v), self.cols), level) for v in views])

    def decode_all(self, level: float = 0) -> np.ndarray:
        """The whole light field: (rows, cols, H, W, C) pixels."""
        return np.stack([np.stack([self.decode_view(r, c, level) for c in range(self.cols)])
                         for r in range(self.rows)])

    def decode_block(self, row: int, col: int, by: int, bx: int, level: float = 0) -> np.ndarray:
        """One block of one view: (b, b, C) pixels, cropped at the image edge."""
        raise UnsupportedError(f"{type(self).__name__} has no block random access (decode views instead)")

    def decode_blocks(self, views, by, bx, level: float = 0) -> np.ndarray:
        """Many blocks: (M, B, B, C) pixels for flat view indices and block rows/columns."""
        raise UnsupportedError(f"{type(self).__name__} has no block random access (decode views instead)")

    @abc.abstractmethod
    def info(self) -> dict:
        """JSON-able description of what this file holds (the CLI prints it without knowing the
        codec): at least ``levels`` and a one-line ``summary``."""


class Codec(abc.ABC):
    """A codec plug-in: registered under ``codec_id`` in the ``lfcodec.codecs`` entry-point group."""

    codec_id: str = ""
    version: int = 1
    description: str = ""

    @abc.abstractmethod
    def encode(self, lf, options: EncodeOptions, progress: Progress | None = None) -> Encoded:
        """Encode a LightField (the codec validates ``options``; bad values raise ParameterError)."""

    @abc.abstractmethod
    def open(self, f, **kw) -> Decoder:
        """A decoder over an opened :class:`~formats.lfcfile.LfcFile` of this codec."""

    def describe(self, f) -> dict:
        """What ``lfcodec info`` says of an opened file (:meth:`Decoder.info` of :meth:`open`'s
        decoder, unless the codec can check and describe the file without building a decoder)."""
        return self.open(f).info()

    #: file-name suffix (lower case) of a set of files this codec writes and opens as one (a
    #: manifest naming the others, e.g. ".json"), or None for codecs that write one .lfc only
    set_suffix: str | None = None

    def writes_set(self, options: EncodeOptions) -> bool:
        """Whether ``options`` ask for a set of files (:meth:`encode_set`) rather than one .lfc."""
        return False

    def encode_set(self, lf, options: EncodeOptions, out, progress: Progress | None = None) -> dict:
        """Encode to a set of files: ``out`` (named with :attr:`set_suffix`) and the files it names,
        beside it, each written atomically. Returns a JSON-able report with at least ``bytes`` (all
        files) and ``files`` (their names)."""
        raise UnsupportedError(f"codec {self.codec_id!r} writes single .lfc files only")

    def open_set(self, source, **kw):
        """A renderer/decoder over a set of files (``source``: the manifest's path or URL)."""
        raise UnsupportedError(f"codec {self.codec_id!r} opens single .lfc files only")

    def add_arguments(self, parser) -> None:
        """Add this codec's own command-line options (an argparse parser or group)."""

    def params_from_args(self, args) -> dict:
        """This codec's params dict from parsed command-line options."""
        return {}
