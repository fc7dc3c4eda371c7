"""The few array operations RLFC's integer kernels need, for numpy and torch alike.

Kernels in :mod:`rlfc.kernels` are written once against this interface: Python operators
(``+ * >> & |``, indexing) behave the same on numpy arrays and torch tensors; the rest is here.
``NUMPY`` is the numpy backend; :func:`torch_backend` builds one for a torch device.
"""
from __future__ import annotations

import numpy as np


class NumpyBackend:
    name = "numpy"
    int32, int64 = np.int32, np.int64

    def asarray(self, a, dtype=None):
        return np.asarray(a, dtype=dtype)

    def arange(self, n, dtype=np.int64):
        return np.arange(n, dtype=dtype)

    def zeros(self, shape, dtype=np.int64):
        return np.zeros(shape, dtype=dtype)

    def repeat(self, a, n: int):
        """Each element of 1-D ``a`` n times in a row."""
        return np.repeat(a, n)

    def where(self, c, a, b):
        return np.where(c, a, b)

    def stack(self, parts, axis):
        return np.stack(parts, axis=axis)

    def cast(self, a, dtype):
        return a.astype(dtype, copy=False)

    uint8 = np.uint8

    def word(self, buf, byte, nbytes: int):
        """Little-endian unsigned word of ``nbytes`` (<= 7) bytes at each byte offset, in the
        narrowest type that holds it here (uint32 up to 4 bytes, else uint64).

        ``buf`` must hold 8 readable bytes after the last offset (the sections' slack)."""
        buf = np.ascontiguousarray(buf)
        if nbytes <= 4:
            v = np.ndarray((buf.size - 3,), dtype="<u4", buffer=buf, strides=(1,))[byte]
            return v if nbytes == 4 else v & np.uint32((1 << (8 * nbytes)) - 1)
        v = np.ndarray((buf.size - 7,), dtype="<u8", buffer=buf, strides=(1,))[byte]
        return v & np.uint64((1 << (8 * nbytes)) - 1)

    def narrow(self, a, bits: int):
        """``a`` (non-negative, < 2^bits) in a 32-bit type when it fits (faster arithmetic)."""
        return a.astype(np.uint32) if bits <= 32 and a.dtype != np.uint32 else a

    def take_rows(self, table, idx):
        return np.take(table, idx, axis=0)

    def flatnonzero(self, a):
        return np.flatnonzero(a)

    def moveaxis(self, a, src, dst):
        return np.moveaxis(a, src, dst)

    def take_cols(self, table, idx):
        """table[:, idx] for a 2-D table (numpy's take is the fast form)."""
        return table.take(idx, axis=1)


class TorchBackend:
    name = "torch"

    def __init__(self, device):
        import torch

        self.t, self.device = torch, device
        self.int32, self.int64, self.uint8 = torch.int32, torch.int64, torch.uint8

    def asarray(self, a, dtype=None):
        t = self.t
        if isinstance(a, t.Tensor):
            return a.to(self.device, dtype) if dtype is not None else a.to(self.device)
        a = np.ascontiguousarray(a)
        if not a.flags.writeable:          # torch wants writable memory; copy read-only views
            a = a.copy()
        return t.as_tensor(a, device=self.device, dtype=dtype)

    def arange(self, n, dtype=None):
        return self.t.arange(n, device=self.device, dtype=dtype or self.t.int64)

    def zeros(self, shape, dtype=None):
        return self.t.zeros(shape, device=self.device, dtype=dtype or self.t.int64)

    def repeat(self, a, n: int):
        return a.repeat_interleave(n)

    def where(self, c, a, b):
        return self.t.where(c, a, b)

    def stack(self, parts, axis):
        return self.t.stack(parts, axis)

    def cast(self, a, dtype):
        return a.to(dtype)

    def narrow(self, a, bits: int):
        return a

    def word(self, buf, byte, nbytes: int):
        """Little-endian word of ``nbytes`` bytes at each byte offset (int64 on torch)."""
        w = buf[byte].to(self.t.int64)
        for i in range(1, nbytes):
            w = w | (buf[byte + i].to(self.t.int64) << (8 * i))
        return w

    def take_rows(self, table, idx):
        return table[idx]

    def flatnonzero(self, a):
        return self.t.nonzero(a).reshape(-1)

    def moveaxis(self, a, src, dst):
        return self.t.movedim(a, src, dst)

    def take_cols(self, table, idx):
        return table[:, idx]


NUMPY = NumpyBackend()


def shared(*tensors):
    """Tensors made once and then read by any CUDA stream (caches of device constants), returned
    once the stream that made them has finished making them: a decode may keep chunks in flight
    on several streams (:mod:`rlfc.torch_decode`), and a stream that reads a tensor another
    stream is still copying or computing reads garbage. Off CUDA: returned as they are."""
    for t in tensors:
        if getattr(t, "is_cuda", False):
            import torch

            torch.cuda.current_stream(t.device).synchronize()
            break
    return tensors[0] if len(tensors) == 1 else tensors


def torch_backend(device) -> TorchBackend:
    import torch

    return TorchBackend(torch.device(device))
