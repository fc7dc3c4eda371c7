"""The protocol every RLFC profile implements.

A profile decides how key views are made and coded, how a block or a view is predicted from
them, what side sections it writes, and which knob its rate control turns. The generic parts
(:mod:`rlfc.codec`, :mod:`rlfc.decoder`, :mod:`rlfc.torch_decode`) only call these methods.

Planes are int32 YCoCg-R (:mod:`formats.pixels`), padded to whole blocks: (…, Hp, Wp, P).
"""
from __future__ import annotations

import abc

import numpy as np


class ProfileDecoder(abc.ABC):
    """An opened file of one profile, reconstructing planes.

    Attributes:
        levels: coarsest progressive level (valid levels 0..levels; 0 = full quality).
        block_size: B, the random-access block edge in pixels.
        nby, nbx: blocks per column and row of the padded view.
    """

    levels: int
    block_size: int
    threads_ok: bool = False      # blocks()/views() may run on several threads at once
    reads_checked: bool = False   # every read of the file's bytes after open checks the file
                                  # (Container.check_unchanged): a call that reads none needs not
    nby: int
    nbx: int

    @abc.abstractmethod
    def blocks(self, views: np.ndarray, by: np.ndarray, bx: np.ndarray, level: int) -> np.ndarray:
        """(M,) validated requests → (M, B·B, P) int32 planes."""

    def block(self, view: int, by: int, bx: int, level: int) -> np.ndarray:
        """One validated request → (B·B, P) int32 planes (override for a leaner scalar path)."""
        return self.blocks(np.array([view]), np.array([by]), np.array([bx]), level)[0]

    @abc.abstractmethod
    def views(self, views: np.ndarray, level: int) -> np.ndarray:
        """(n,) validated view indices → (n, Hp, Wp, P) int32 planes."""

    def prepare(self, views: np.ndarray, by: np.ndarray) -> None:
        """Called once before a batch of validated requests is decoded in chunks (possibly on
        several threads): a profile that decodes shared data on demand (the ``tx`` key-view
        rows) does it here, in one pass, instead of once per chunk. Default: nothing."""

    def view_groups(self, views: np.ndarray) -> list:
        """How :meth:`views` is best called for many views (a list of index arrays); default: all
        at once (profiles that share work across views)."""
        return [views]

    def torch(self, device):
        """A batched decoder of the same planes on a torch device (``blocks`` returns tensors)."""
        from formats.errors import UnsupportedError

        raise UnsupportedError(f"profile {type(self).__name__} has no torch decoder")

    def info(self) -> dict:
        return {}


class Profile(abc.ABC):
    """An RLFC profile plug-in."""

    id: str = ""
    description: str = ""

    def accepts(self, lf) -> str | None:
        """None if this profile can code ``lf``, else why not (one line)."""
        return None

    @abc.abstractmethod
    def encode(self, lf, options, progress=None):
        """Encode with :class:`formats.codec_api.EncodeOptions` → :class:`formats.codec_api.Encoded`."""

    @abc.abstractmethod
    def open(self, container, header, cfg) -> ProfileDecoder:
        """Decoder over a container, given the validated common header
        (:class:`rlfc.header.RlfcHeader`) and the config as :class:`formats.schema.Fields`."""
