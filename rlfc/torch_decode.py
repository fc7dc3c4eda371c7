"""Batched RLFC block decode with torch, on a GPU when one is present.

The profile copies what it needs (compressed blocks, key views, side tables) to the device
once; the integer kernels are the same functions the numpy decoder runs (:mod:`rlfc.kernels`),
so the result equals :meth:`rlfc.decoder.RlfcDecoder.decode_blocks` bit for bit.
"""
from __future__ import annotations

import contextlib
import threading
from concurrent.futures import ThreadPoolExecutor

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
#: chunks in flight at once on a CUDA device by default, each from its own host thread on its own
#: stream: a chunk's parse waits for the device several times (its sizes depend on the data), and
#: the other chunk's kernels are queued meanwhile, so the device is not left idle while the host
#: works. Two measured 1.0-1.56x the speed of one on an H200 (BENCHMARKS.md), but their pixels
#: have been compared with numpy's on the CPU device only, so one stays the default until a GPU
#: run checks them (``TorchBlockDecoder(d, in_flight=2)`` asks for two)
PIPELINE = 1
#: ... for calls of at least this many requests (split into at least PIPELINE chunks)
PIPELINE_MIN = 1 << 15


def chunk_for(device, in_flight: int = 1) -> int:
    """Requests decoded together on ``device`` (per chunk, ``in_flight`` chunks at once): as
    many as :data:`DEVICE_SHARE` of a CUDA device's free memory holds (:data:`CPU_BUDGET` on
    the CPU), within MIN_CHUNK..CHUNK."""
    if device.type == "cuda":
        free, _ = torch.cuda.mem_get_info(device)
        budget = DEVICE_SHARE * free
    else:
        budget = CPU_BUDGET
    return int(min(CHUNK, max(MIN_CHUNK, budget // (BYTES_PER_REQUEST * in_flight))))


def _out_of_memory(e: BaseException) -> bool:
    oom = getattr(torch, "OutOfMemoryError", None) or getattr(torch.cuda, "OutOfMemoryError", None)
    return oom is not None and isinstance(e, oom)


class TorchBlockDecoder:
    """Batched block decoder on a torch device, over an :class:`~rlfc.decoder.RlfcDecoder`.

    Args:
        dec: an opened RLFC decoder (memory-mapped or in-memory file).
        device: torch device; default "cuda" when available, else "cpu".
        in_flight: chunks of a large call (:data:`PIPELINE_MIN` requests or more) decoded at once
            on a CUDA device, each by its own host thread on its own stream (default
            :data:`PIPELINE`; always 1 off CUDA).
    """

    def __init__(self, dec, device: str | None = None, in_flight: int | None = None):
        self.d = dec
        self.dev = torch_device(device)
        self.core = dec.core.torch(self.dev)
        self.peak = int(np.iinfo(dec.dtype).max)
        #: chunks in flight at once (``in_flight`` or :data:`PIPELINE` on a CUDA device, 1 elsewhere)
        self.in_flight = max(1, int(PIPELINE if in_flight is None else in_flight)) if self.dev.type == "cuda" else 1
        self._local = threading.local()
        self._pool = None                   # (lanes, the host threads of :meth:`_pipelined`), kept: each keeps its stream
        self._pool_lock = threading.Lock()

    def decode_blocks(self, views, by, bx, level: int = 0, to_numpy: bool = True):
        """Same contract as :meth:`RlfcDecoder.decode_blocks`; returns numpy (or a device tensor)."""
        d = self.d
        level = d.check_level(level)
        views, by, bx = d.requests(views, by, bx)
        B, M = d.block_size, views.size
        out = None
        step = chunk_for(self.dev)                     # bounded temporaries (~80 KB a request)
        if self.in_flight > 1 and M >= PIPELINE_MIN:
            try:
                out = self._pipelined(views, by, bx, level, self.in_flight)
            except Exception as e:                     # the device ran out: one chunk at a time, halved
                if not _out_of_memory(e):
                    raise
                step = max(MIN_CHUNK, chunk_for(self.dev, self.in_flight) // 2)
                if self.dev.type == "cuda":
                    torch.cuda.empty_cache()
        i = 0 if out is None else M
        while i < M or out is None:
            sl = slice(i, i + step)
            try:
                got = self._chunk(views[sl], by[sl], bx[sl], level)
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

    def _chunk(self, views, by, bx, level):
        """One chunk's blocks, clipped: (n, B, B, P) device tensor."""
        d = self.d
        acc = self.core.blocks(views, by, bx, level).reshape(-1, d.block_size, d.block_size, d.P)
        return torch.clamp(inverse_int(acc), 0, self.peak)

    def _stream(self):
        """This host thread's CUDA stream (None off CUDA); the threads live as long as the
        decoder, so the streams do too (a new stream would start with an empty share of torch's
        caching allocator, and fill it with fresh device allocations)."""
        if self.dev.type != "cuda":
            return None
        s = getattr(self._local, "stream", None)
        if s is None:
            s = self._local.stream = torch.cuda.Stream(self.dev)
        return s

    def _pipelined(self, views, by, bx, level, lanes: int):
        """All requests in equal chunks, ``lanes`` of them decoded at once by as many host
        threads, each on its own stream; the chunks are joined on the caller's stream."""
        M = views.size
        n = max(lanes, -(-M // chunk_for(self.dev, lanes)))
        size = -(-M // n)
        cuda = self.dev.type == "cuda"
        main = torch.cuda.current_stream(self.dev) if cuda else None

        failed = threading.Event()

        def run(k):
            if failed.is_set():                        # a chunk failed: start no more
                return None
            sl = slice(k * size, (k + 1) * size)
            s = self._stream()
            try:
                with torch.cuda.stream(s) if cuda else contextlib.nullcontext():
                    if cuda:
                        s.wait_stream(main)            # the device tables were made on the caller's stream
                    got = self._chunk(views[sl], by[sl], bx[sl], level)
                    done = None
                    if cuda:
                        done = torch.cuda.Event()
                        done.record(s)
            except BaseException:
                failed.set()
                raise
            return sl, got, done

        with self._pool_lock:                          # one pipelined call at a time per decoder
            if self._pool is None or self._pool[0] != lanes:
                if self._pool is not None:
                    self._pool[1].shutdown()
                self._pool = (lanes, ThreadPoolExecutor(lanes, thread_name_prefix="lfc-decode"))
            parts = list(self._pool[1].map(run, range(n)))
        out = None
        for sl, got, done in parts:
            if cuda:
                main.wait_event(done)
                got.record_stream(main)                # read on the caller's stream: not reused before
            if out is None:
                out = torch.empty((M,) + tuple(got.shape[1:]), dtype=got.dtype, device=got.device)
            out[sl] = got
        return out
