"""The pixel operations of the novel-view renderer, for numpy (OpenCV) and torch alike.

:class:`rlfc.render.Renderer` writes each frame once against this interface; Python operators
(``+ - * <``, slicing) behave the same on numpy arrays and torch tensors, the rest is here.
``NumpyOps`` samples with OpenCV's ``remap``; ``TorchOps`` gathers the taps itself on a torch
device (a GPU when present); both interpolate at the exact float positions (OpenCV 5's remap of float32
images does not round them to 1/32 pixel as OpenCV 4 did), so both give the same frames within
float rounding.

Shapes: positions and scalar planes (H, W) float32; sampled pixels (H, W, P) float32, P planes
of the file (YCoCg-R [+ alpha] or grey [+ alpha]); a view buffer holds a view's decoded blocks,
(nby·B, nbx·B) pixels, zero where a block is not decoded yet.
"""
from __future__ import annotations

import numpy as np

from . import cvremap

TILE = 8               # the geometry's block: tile extents and block maps are per 8×8 pixels


def median_f32(a: np.ndarray) -> np.float32:
    """``np.median`` of a float32 array (all its values), the same value: the middle one, or
    the float32 mean of the two middle ones (NaN where any value is NaN). Without
    ``np.median``, whose first call in a process imports ``numpy.ma`` (~17 ms of a first frame
    on the 2-core box)."""
    v = np.asarray(a, np.float32).reshape(-1)
    n = v.size
    if n == 0 or np.isnan(v).any():
        return np.float32(np.nan)
    k = n // 2
    if n % 2:
        return np.partition(v, k)[k]
    p = np.partition(v, (k - 1, k))
    return (p[k - 1] + p[k]) / np.float32(2)


class NumpyOps:
    """numpy + OpenCV, on the CPU (the default)."""

    name = "numpy"

    def grid(self, H: int, W: int):
        yy = np.broadcast_to(np.arange(H, dtype=np.float32)[:, None], (H, W)).copy()
        xx = np.broadcast_to(np.arange(W, dtype=np.float32)[None, :], (H, W)).copy()
        return yy, xx

    def const(self, H: int, W: int, v: float):
        return np.full((H, W), v, np.float32)

    def from_blocks(self, m: np.ndarray, H: int, W: int):
        """(H, W) float32: a per-8×8-block map (ny, nx) repeated over its blocks' pixels."""
        return np.repeat(np.repeat(np.asarray(m, np.float32), TILE, 0), TILE, 1)[:H, :W]

    def from_blocks_many(self, maps, H: int, W: int):
        """:meth:`from_blocks` of each map of a list."""
        return [self.from_blocks(m, H, W) for m in maps]

    def buffer(self, h: int, w: int, P: int):
        return np.zeros((h, w, P), np.float32)

    def put_blocks(self, buf, by, bx, got: np.ndarray, B: int) -> None:
        """Write decoded blocks ``got`` (n, B, B, P) at block rows ``by`` / columns ``bx``."""
        h, w, P = buf.shape
        buf.reshape(h // B, B, w // B, B, P)[by, :, bx, :, :] = got.reshape(-1, B, B, P)

    def clamp(self, a, hi: float):
        return np.minimum(np.maximum(a, 0, out=a), hi, out=a)

    def clamp_all(self, planes, hi: float):
        """Each plane of ``planes`` (a list here; a stacked tensor on torch) clamped to [0, hi]."""
        return [self.clamp(a, hi) for a in planes]

    def shifted(self, base, planes, offs):
        """Positions ``base + D · o`` (float32: the product rounded, then the sum) for each
        disparity plane D of ``planes`` and each offset o of ``offs`` (view steps), D-major: a list
        of len(planes)·len(offs) planes here, one stacked tensor on torch."""
        return [base + D * float(o) for D in planes for o in offs]

    def plus_affine(self, pos, yy, xx, coefs, reps: int = 1):
        """``pos`` (a list of planes here) each plus its affine plane c0·yy + c1·xx + c2 (float32;
        per-view warps, :mod:`rlfc.txwarp`): ``coefs`` (n, 3), the list ``reps`` times over
        (candidate-major positions of n sources)."""
        n = len(coefs)
        return [p + (yy * np.float32(c[0]) + xx * np.float32(c[1]) + np.float32(c[2]))
                for p, c in zip(pos, [coefs[i % n] for i in range(n * reps)])]

    def disagreement(self, lum, ws, k: int, kb: int):
        """Per candidate, the box mean over k×k (:meth:`blur`) of the weighted variance of its n
        sources' luma around their weighted mean, each source's luma less its own box mean over
        kb×kb first (its brightness there: vignetting or exposure that differs per view is no
        disagreement about geometry): ``lum`` K·n planes (candidate-major), ``ws`` the n weights;
        a list of K planes."""
        n = len(ws)
        costs = []
        for i in range(0, len(lum), n):
            smp = [x - self.blur(x, kb) for x in lum[i:i + n]]
            costs.append(self.blur(self.wsum(self.sq_dev(smp, self.wsum(smp, ws)), ws), k))
        return costs

    def tile_range(self, a):
        """(min, max) over each 8×8 tile of ``a`` (H, W), numpy (ceil(H/8), ceil(W/8)); edge
        tiles cover what they hold."""
        import cv2

        k = np.ones((TILE, TILE), np.uint8)
        lo = cv2.erode(a, k, anchor=(0, 0), borderType=cv2.BORDER_REPLICATE)[::TILE, ::TILE]
        hi = cv2.dilate(a, k, anchor=(0, 0), borderType=cv2.BORDER_REPLICATE)[::TILE, ::TILE]
        return lo, hi

    def remap(self, buf, X, Y, cubic: bool = False):
        """(H, W, P) samples of ``buf`` at positions (Y, X) (inside the buffer): bilinear, or
        bicubic (Keys, a = −0.75; taps past the buffer repeat its edge), at the exact positions.
        (OpenCV 5.0 rounds the positions of a two-channel bilinear remap to 1/32 pixel, as
        OpenCV 4 did, and takes the others exactly: such buffers are sampled plane by plane.)"""
        import cv2

        if buf.shape[2] == 2 and not cubic:
            out = np.empty((*Y.shape, 2), buf.dtype)
            for p in range(2):
                out[..., p] = cvremap.remap(np.ascontiguousarray(buf[..., p]), X, Y, cv2.INTER_LINEAR).reshape(Y.shape)
            return out
        out = cvremap.remap(buf, X, Y, cv2.INTER_CUBIC if cubic else cv2.INTER_LINEAR)
        return out.reshape(*Y.shape, buf.shape[2])

    def tile_ranges(self, planes):
        """:meth:`tile_range` of each plane of a list, stacked: numpy (lo, hi), each (n, ty, tx)."""
        got = [self.tile_range(a) for a in planes]
        return np.stack([g[0] for g in got]), np.stack([g[1] for g in got])

    def remap_many(self, bufs, Xs, Ys, cubic: bool = False):
        """:meth:`remap` of each (buffer, X, Y): a list of (H, W, P) samples (``wsum`` reads it)."""
        return [self.remap(b, X, Y, cubic) for b, X, Y in zip(bufs, Xs, Ys)]

    def plane(self, samples, p: int):
        """Plane p of each sample of :meth:`remap_many`."""
        return [x[..., p] for x in samples]

    def wsum(self, samples, ws, acc=None):
        """acc + Σ w_i · samples_i (scalar weights), accumulated in order (from zero when
        ``acc`` is None) in float32."""
        acc = np.zeros(samples[0].shape, np.float32) if acc is None else acc
        for w, x in zip(ws, samples):
            acc += np.float32(w) * x
        return acc

    def sq_dev(self, samples, mean):
        """(x_i − mean)² of each sample."""
        return [(x - mean) ** 2 for x in samples]

    def blur(self, a, k: int):
        """Box mean over k×k pixels (anchor k//2, mirrored edges without repeating the edge)."""
        import cv2

        return cv2.blur(a, (k, k))

    def where(self, c, a, b):
        return np.where(c, a, b)

    def zeros_int(self, shape):
        return np.zeros(shape, np.int64)

    def choose(self, sel, S: int, H: int, W: int, cands):
        """(H, W) float32: per S×S cell, ``cands[k]`` at the cell's grid point, k from ``sel``
        (both on the grid of every S-th pixel), repeated over the cell. Choosing per pixel gives
        the same planes where every candidate is constant over each cell (the renderer's are
        per 8×8 block, or one value, and S divides 8); here only the grid points are chosen."""
        v = np.choose(sel, cands).astype(np.float32, copy=False)
        return np.repeat(np.repeat(v, S, 0), S, 1)[:H, :W]

    def sub(self, a, S: int):
        return np.ascontiguousarray(a[::S, ::S])

    def to_numpy(self, a) -> np.ndarray:
        return a

    def to_pixels(self, planes, dtype) -> np.ndarray:
        """(H, W, C) pixels of ``dtype``: planes rounded half to even, colour transform inverted,
        clipped."""
        from formats.pixels import from_planes

        return from_planes(np.rint(planes).astype(np.int32), dtype)


class TorchOps:
    """torch on a device ("cuda" when available, else "cpu"): bilinear taps by gather."""

    name = "torch"

    def __init__(self, device: str | None = None):
        import torch

        from formats.devices import torch_device

        self.torch = torch
        self.F = torch.nn.functional
        self.dev = torch_device(device)

    def grid(self, H: int, W: int):
        t = self.torch
        yy = t.arange(H, device=self.dev, dtype=t.float32)[:, None].expand(H, W).contiguous()
        xx = t.arange(W, device=self.dev, dtype=t.float32)[None, :].expand(H, W).contiguous()
        return yy, xx

    def const(self, H: int, W: int, v: float):
        return self.torch.full((H, W), float(v), dtype=self.torch.float32, device=self.dev)

    def from_blocks_many(self, maps, H: int, W: int):
        """All maps in one host-to-device copy (each copy from pageable memory waits for the
        device's queue: a frame makes its copies before any kernel)."""
        t = self.torch.as_tensor(np.stack([np.asarray(m, np.float32) for m in maps]), device=self.dev)
        return list(t.repeat_interleave(TILE, 1).repeat_interleave(TILE, 2)[:, :H, :W])

    def buffer(self, h: int, w: int, P: int):
        return self.torch.zeros((h, w, P), dtype=self.torch.float32, device=self.dev)

    def put_blocks(self, buf, by, bx, got: np.ndarray, B: int) -> None:
        h, w, P = buf.shape
        g = self.torch.as_tensor(got.reshape(-1, B, B, P), device=self.dev).to(self.torch.float32)
        iy = self.torch.as_tensor(by, device=self.dev)
        ix = self.torch.as_tensor(bx, device=self.dev)
        buf.view(h // B, B, w // B, B, P)[iy, :, ix, :, :] = g

    def clamp(self, a, hi: float):
        return a.clamp_(0, hi)

    def clamp_all(self, planes, hi: float):
        if isinstance(planes, self.torch.Tensor):
            return planes.clamp_(0, hi)
        return [a.clamp_(0, hi) for a in planes]

    def vector(self, values, dtype=None):
        """A small vector (float32, or ``dtype``) on the device, copied from pinned memory without
        waiting for the device's queue (a copy from pageable memory would wait for the kernels
        queued before it)."""
        x = self.torch.tensor(list(values), dtype=dtype or self.torch.float32)
        if self.dev.type == "cuda":
            return x.pin_memory().to(self.dev, non_blocking=True)
        return x.to(self.dev)

    def shifted(self, base, planes, offs):
        """As :meth:`NumpyOps.shifted`: one (len(planes)·len(offs), H, W) tensor in two kernels."""
        D = self.torch.stack(list(planes)) if len(planes) > 1 else planes[0][None]
        o = self.vector(offs)
        return (D[:, None] * o[None, :, None, None] + base[None, None]).reshape(-1, *base.shape)

    def plus_affine(self, pos, yy, xx, coefs, reps: int = 1):
        """As :meth:`NumpyOps.plus_affine`: ``pos`` (reps·n, H, W)."""
        c = self.vector(np.tile(np.asarray(coefs, np.float64), (reps, 1)).reshape(-1))
        c = c.view(-1, 3)[:, :, None, None]
        return pos + (yy[None] * c[:, 0] + xx[None] * c[:, 1] + c[:, 2])

    def disagreement(self, lum, ws, k: int, kb: int):
        """As :meth:`NumpyOps.disagreement`, every candidate at once: ``lum`` (K·n, h, w)."""
        n = len(ws)
        w = self.vector(ws).view(1, n, 1, 1)
        L = lum - self.blur(lum, kb)
        L = L.reshape(-1, n, *lum.shape[1:])                          # (K, n, h, w)
        mean = (L * w).sum(1, keepdim=True)
        var = ((L - mean) ** 2 * w).sum(1)                             # (K, h, w)
        return list(self.blur(var, k))

    def tile_ranges(self, planes):
        """As :meth:`NumpyOps.tile_ranges`: two pooling calls and one device-to-host copy."""
        F, t = self.F, self.torch
        x = t.stack(planes)[:, None]
        both = t.stack([-F.max_pool2d(-x, TILE, TILE, ceil_mode=True), F.max_pool2d(x, TILE, TILE, ceil_mode=True)])
        both = both[:, :, 0].cpu().numpy()
        return both[0], both[1]

    def remap_many(self, bufs, Xs, Ys, cubic: bool = False):
        """(S, H, W, P) samples of S buffers at their positions, all taps of all of them gathered
        in one indexing call from the stacked buffers (few kernel launches per frame), with
        weights at the exact float positions (as OpenCV 5 computes them; not ``grid_sample``,
        whose normalized coordinates lose ~1e-5 pixel): bilinear, or bicubic (Keys, a = −0.75,
        edge taps repeated)."""
        t = self.torch
        h, w, P = bufs[0].shape
        S = len(bufs)
        slot = {}                                  # a view sampled at several positions is stacked once
        which = [slot.setdefault(id(b), len(slot)) for b in bufs]
        uniq = list({id(b): b for b in bufs}.values())
        src = (t.stack(uniq) if len(uniq) > 1 else uniq[0][None]).view(len(uniq) * h * w, P)
        XY = t.stack([t.stack(list(Xs)) if isinstance(Xs, list) else Xs,
                      t.stack(list(Ys)) if isinstance(Ys, list) else Ys])   # (2, S, H, W)
        xy0 = t.floor(XY)
        f = XY - xy0
        xy0 = xy0.to(t.int64)
        x0, y0 = xy0[0], xy0[1]
        if cubic:
            k = t.arange(-1, 3, device=self.dev).view(4, 1, 1, 1)
            xs = (x0[None] + k).clamp_(0, w - 1)
            ys = (y0[None] + k).clamp_(0, h - 1) * w
            wxy = t.stack(keys_weights(f), 1)                                # (2, 4, S, H, W)
        else:
            xs = t.stack([x0, (x0 + 1).clamp_(max=w - 1)])
            ys = t.stack([y0, (y0 + 1).clamp_(max=h - 1)]) * w
            wxy = t.stack([1 - f, f], 1)
        wx, wy = wxy[0], wxy[1]
        base = t.arange(S, device=self.dev) if which == list(range(S)) else \
            self.vector(which, t.int64)
        ys = ys + (base * (h * w)).view(1, S, 1, 1)
        taps = src[(ys[:, None] + xs[None]).reshape(-1)].view(*ys.shape[:1], *xs.shape, P)  # (ty, tx, S, H, W, P)
        rows = (taps * wx[None, ..., None]).sum(1)
        return (rows * wy[..., None]).sum(0)

    def plane(self, samples, p: int):
        return samples[..., p]

    def wsum(self, samples, ws, acc=None):
        # two or fewer: weights as Python scalars; more: one weighted sum over a weight vector
        # copied from pinned memory (a copy from pageable memory would wait for the device's queue)
        if len(ws) > 2:
            w = self.vector(ws).view(-1, *([1] * (samples.dim() - 1)))
            out = (samples * w).sum(0)
            return out if acc is None else acc.add_(out)
        if acc is None:
            acc = samples[0] * float(ws[0])
            samples, ws = samples[1:], ws[1:]
        for x, w in zip(samples, ws):
            acc.add_(x, alpha=float(w))
        return acc

    def sq_dev(self, samples, mean):
        return (samples - mean[None]) ** 2

    def blur(self, a, k: int):
        F = self.F
        a0 = k // 2                                        # OpenCV's anchor, reflect-101 edges
        mode = "reflect" if min(a.shape[-2:]) > a0 else "replicate"     # (reflect needs a wider plane)
        x = F.pad(a.reshape(-1, 1, *a.shape[-2:]), (a0, k - 1 - a0, a0, k - 1 - a0), mode=mode)
        return F.avg_pool2d(x, k, stride=1).view(a.shape)              # (…, h, w): planes at once

    def where(self, c, a, b):
        return self.torch.where(c, a, b)

    def zeros_int(self, shape):
        return self.torch.zeros(shape, dtype=self.torch.int64, device=self.dev)

    def choose(self, sel, S: int, H: int, W: int, cands):
        out = cands[0]
        for i, c in enumerate(cands[1:], 1):
            out = self.torch.where(sel == i, c, out)
        return out.repeat_interleave(S, 0).repeat_interleave(S, 1)[:H, :W]

    def sub(self, a, S: int):
        return a[::S, ::S].contiguous()

    def to_numpy(self, a) -> np.ndarray:
        return a.cpu().numpy()

    def to_pixels(self, planes, dtype) -> np.ndarray:
        """As :meth:`NumpyOps.to_pixels`, on the device (one small copy back)."""
        from formats.pixels import inverse_int

        t = self.torch
        peak = int(np.iinfo(dtype).max)
        x = inverse_int(t.round(planes).to(t.int32)).clamp_(0, peak)
        return (x.to(t.uint8) if peak == 255 else x).cpu().numpy().astype(dtype, copy=False)


def keys_weights(f):
    """The four cubic-convolution weights (taps at −1, 0, +1, +2) at fractions ``f``, Keys' kernel
    with a = −0.75 written as OpenCV writes it (the fourth is one minus the others)."""
    A = -0.75
    f1, g = f + 1, 1 - f
    w0 = ((A * f1 - 5 * A) * f1 + 8 * A) * f1 - 4 * A
    w1 = ((A + 2) * f - (A + 3)) * f * f + 1
    w2 = ((A + 2) * g - (A + 3)) * g * g + 1
    return w0, w1, w2, 1 - w0 - w1 - w2


def make_ops(device: str | None):
    """The ops for ``device``: None or "numpy" → numpy + OpenCV; "auto" → torch on a CUDA GPU when
    one is present, else numpy; "cpu", "cuda", "cuda:1", "mps" … → torch there (ParameterError
    when that device is not usable)."""
    if device == "auto":
        from formats.devices import cuda_available

        device = "cuda" if cuda_available() else None
    if device is None or device == "numpy":
        return NumpyOps()
    if not isinstance(device, str):
        from formats.errors import ParameterError

        raise ParameterError(f"device must be a string such as 'cuda' or 'cpu', got {device!r}")
    return TorchOps(device)
