"""Batched RLFC block decode with torch, on a GPU when one is present.

The profile copies what it needs (compressed blocks, key views, side tables) to the device
once; the integer kernels are the same functions the numpy decoder runs (:mod:`rlfc.kernels`),
so the result equals :meth:`rlfc.decoder.RlfcDecoder.decode_blocks` bit for bit.
"""
from __future__ import annotations

import numpy as np
import torch

from formats.devices import torch_device
from formats.pixels import inverse_int

CHUNK = 1 << 17         # requests decoded together: the device's temporaries grow with them


class TorchBlockDecoder:
    """Batched block decoder on a torch device, over an :class:`~rlfc.decoder.RlfcDecoder`.

    Args:
        dec: an opened RLFC decoder (memory-mapped or in-memory file).
        device: torch device; default "cuda" when available, else "cpu".
    """

    def __init__(self, dec, device: str | None = None):
        self.d = dec
        self.dev = torch_device(device)
        self.core = dec.core.torch(self.dev)
        self.peak = int(np.iinfo(dec.dtype).max)

    def decode_blocks(self, views, by, bx, level: int = 0, to_numpy: bool = True):
        """Same contract as :meth:`RlfcDecoder.decode_blocks`; returns numpy (or a device tensor)."""
        d = self.d
        level = d.check_level(level)
        views, by, bx = d.requests(views, by, bx)
        B = d.block_size
        out = None
        for i in range(0, max(views.size, 1), CHUNK):  # bounded temporaries (~6 GB per chunk on tx)
            sl = slice(i, i + CHUNK)
            acc = self.core.blocks(views[sl], by[sl], bx[sl], level).reshape(-1, B, B, d.P)
            got = torch.clamp(inverse_int(acc), 0, self.peak)
            if views.size <= CHUNK:
                out = got
                break
            if out is None:
                out = torch.empty((views.size, B, B, d.P), dtype=got.dtype, device=got.device)
            out[sl] = got
        return out.cpu().numpy().astype(d.dtype) if to_numpy else out
