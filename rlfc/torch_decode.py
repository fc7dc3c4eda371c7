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

CHUNK = 1 << 17         # requests decoded together at most (a GPU's kernels fill with ~10^5)
MIN_CHUNK = 1 << 10     # ... and at least, unless the call has fewer
#: device memory a request's temporaries take at peak (the tx profile, numpy-equal integer
#: kernels in int64: 56–74 KB measured on the CPU device, residual-heavy and predicted grids)
BYTES_PER_REQUEST = 80 << 10
#: share of a CUDA device's free memory a call's temporaries may take; host memory for the CPU device
DEVICE_SHARE = 0.5
CPU_BUDGET = 1 << 30


def chunk_for(device) -> int:
    """Requests decoded together on ``device``: as many as :data:`DEVICE_SHARE` of a CUDA
    device's free memory holds (:data:`CPU_BUDGET` on the CPU), within MIN_CHUNK..CHUNK."""
    if device.type == "cuda":
        free, _ = torch.cuda.mem_get_info(device)
        budget = DEVICE_SHARE * free
    else:
        budget = CPU_BUDGET
    return int(min(CHUNK, max(MIN_CHUNK, budget // BYTES_PER_REQUEST)))


def _out_of_memory(e: BaseException) -> bool:
    oom = getattr(torch, "OutOfMemoryError", None) or getattr(torch.cuda, "OutOfMemoryError", None)
    return oom is not None and isinstance(e, oom)


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
        B, M = d.block_size, views.size
        out = None
        step = chunk_for(self.dev)                     # bounded temporaries (~80 KB a request)
        i = 0
        while i < M or out is None:
            sl = slice(i, i + step)
            try:
                acc = self.core.blocks(views[sl], by[sl], bx[sl], level).reshape(-1, B, B, d.P)
                got = torch.clamp(inverse_int(acc), 0, self.peak)
            except Exception as e:                     # the device ran out: half the requests, again
                if not _out_of_memory(e) or step <= MIN_CHUNK:
                    raise
                step = max(MIN_CHUNK, min(step, M - i) // 2)
                if self.dev.type == "cuda":
                    torch.cuda.empty_cache()
                continue
            if M <= step and i == 0:
                out = got
                break
            if out is None:
                out = torch.empty((M, B, B, d.P), dtype=got.dtype, device=got.device)
            out[sl] = got
            i += step
        return out.cpu().numpy().astype(d.dtype) if to_numpy else out
