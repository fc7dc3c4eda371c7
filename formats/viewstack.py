"""Views read one at a time from any array users already have: a numpy array or memmap, a zarr
array, a dask array (anything with ``shape``, ``dtype`` and integer indexing whose items
``np.asarray`` turns into pixels).

``ViewStack(arr, grid=(R, C))`` presents an (N, H, W, Ch) or (R, C, H, W, Ch) array as the
(R, C, H, W, Ch) ``views`` of a :class:`~formats.lightfield.LightField` without reading it:
``stack[r, c]`` reads one view; ``np.asarray(stack)`` reads all of them (view by view into one
array). The ``tx`` profile reads views when it codes them, so an encode from a zarr or dask
array never holds the whole light field as pixels (other profiles read it all first).
"""
from __future__ import annotations

import numpy as np

from .errors import SceneError


class ViewStack:
    """(R, C, H, W, Ch) views over an array-like, read one view per ``stack[r, c]``.

    Args:
        arr: (N, H, W, Ch), (N, H, W) grey, (R, C, H, W, Ch) or (R, C, H, W) array-like of
            uint8 / uint16 / float32 samples.
        grid: (R, C) with R·C = N for an (N, ...) array; None for a 5-d array, or (1, N).
    """

    ndim = 5

    def __init__(self, arr, grid: tuple[int, int] | None = None):
        if isinstance(arr, (list, tuple)):            # a list of views of one shape: stacked
            try:
                arr = np.stack([np.asarray(x) for x in arr]) if arr else np.zeros((0, 0, 0), np.uint8)
            except ValueError:
                raise SceneError("views given as a list must all have one shape") from None
        shape = tuple(int(x) for x in getattr(arr, "shape", ()))
        if not hasattr(arr, "dtype") or len(shape) not in (3, 4, 5):
            what = f"shape {shape}" if hasattr(arr, "shape") else type(arr).__name__
            raise SceneError(f"views must be an array of (N, H, W[, C]) or (R, C, H, W, C), got {what}")
        if grid is not None and not (len(grid) == 2 and all(isinstance(g, (int, np.integer)) and not
                                                           isinstance(g, bool) and g >= 1 for g in grid)):
            raise SceneError(f"grid must be (rows, cols) of positive integers, got {grid!r}")
        if len(shape) == 5:
            r, c = shape[:2]
            hwc = shape[2:]
            self._five = True
        else:
            n = shape[0]
            hwc = shape[1:] if len(shape) == 4 else shape[1:] + (1,)
            r, c = grid if grid is not None else (1, n)
            if r * c != n:
                raise SceneError(f"grid {r}x{c} does not hold the {n} views of the array")
            self._five = False
        self.arr = arr
        self.shape = (int(r), int(c)) + tuple(hwc)
        self.dtype = np.dtype(arr.dtype)
        self.nbytes = int(np.prod(self.shape)) * self.dtype.itemsize

    def view(self, r: int, c: int) -> np.ndarray:
        """(H, W, Ch) pixels of view (r, c), read now."""
        if not (0 <= r < self.shape[0] and 0 <= c < self.shape[1]):
            raise IndexError(f"view ({r}, {c}) outside the {self.shape[0]}x{self.shape[1]} grid")
        x = self.arr[r, c] if self._five else self.arr[r * self.shape[1] + c]
        x = np.asarray(x)
        if x.ndim == 2:
            x = x[..., None]
        if x.shape != self.shape[2:] or x.dtype != self.dtype:
            raise SceneError(f"view ({r}, {c}) reads as {x.shape} {x.dtype}, expected {self.shape[2:]} {self.dtype}")
        return x

    def __getitem__(self, key):
        if isinstance(key, tuple) and len(key) == 2 and all(isinstance(k, (int, np.integer)) for k in key):
            return self.view(int(key[0]), int(key[1]))
        return np.asarray(self)[key]

    def __array__(self, dtype=None, copy=None):
        out = np.empty(self.shape, self.dtype)
        for r in range(self.shape[0]):
            for c in range(self.shape[1]):
                out[r, c] = self.view(r, c)
        return out if dtype is None else out.astype(dtype)

    def __len__(self):
        return self.shape[0]

    def __repr__(self):
        return f"ViewStack(shape={self.shape}, dtype={self.dtype}, over {type(self.arr).__name__})"


def from_array(arr, grid: tuple[int, int] | None = None, **kw):
    """A :class:`~formats.lightfield.LightField` over ``arr`` (see :class:`ViewStack`), read
    lazily: a regular grid with unit baseline unless ``positions`` / ``layout`` / ``focal`` ...
    are given (keyword arguments of LightField)."""
    from .lightfield import LightField, grid_positions

    vs = arr if isinstance(arr, ViewStack) else ViewStack(arr, grid)
    kw.setdefault("positions", grid_positions(vs.shape[0], vs.shape[1]))
    return LightField(views=vs, **kw)


def view_of(views, v: int) -> np.ndarray:
    """(H, W, Ch) pixels of view v (row-major index) of (R, C, H, W, Ch) views, whatever holds them."""
    cols = views.shape[1]
    return np.asarray(views[v // cols, v % cols])


__all__ = ["ViewStack", "from_array", "view_of"]
