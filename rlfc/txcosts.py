"""The luma costs the ``tx`` maps' estimate ranks candidates by (:class:`Estimator`): per cell of
views, 8×8 block and prediction mode, the squared error of the key views sampled at a whole-pixel
disparity shared by every block (the global sweep) or at each block's own disparity (1/16 px),
computed cell by cell on a runner's threads, with per-thread scratch arrays.
"""
from __future__ import annotations

import threading
from contextlib import contextmanager

import numpy as np

from formats.parallel import Runner

from . import cvremap
from .txlayout import MAX_REFS
from .txpredict import TB
from .txwarp import pair_params, view_offsets


def _shift(img: np.ndarray, dy: float, dx: float, out: np.ndarray | None = None) -> np.ndarray:
    """(H, W) float32 ``img`` shifted (into ``out`` where given): out[y, x] = img[clip(y + dy), clip(x + dx)], edges
    replicated; the same values as OpenCV's bilinear ``warpAffine`` (inverse map, replicated
    border), which whole-pixel shifts (the global sweep's) take as a crop and a border copy."""
    import cv2

    h, w = img.shape
    if dy == int(dy) and dx == int(dx) and abs(dy) < h and abs(dx) < w:
        dy, dx = int(dy), int(dx)
        crop = img[max(dy, 0):h + min(dy, 0), max(dx, 0):w + min(dx, 0)]
        return cv2.copyMakeBorder(crop, max(-dy, 0), max(dy, 0), max(-dx, 0), max(dx, 0), cv2.BORDER_REPLICATE,
                                  dst=out)
    if max(h, w) > cvremap.SIDE:        # (OpenCV's warps address images below 32767 px a side)
        gy, gx = np.mgrid[0:h, 0:w].astype(np.float32)
        return cvremap.remap(img, gx + np.float32(dx), gy + np.float32(dy), cv2.INTER_LINEAR, out=out)
    mat = np.float32([[1, 0, dx], [0, 1, dy]])
    return cv2.warpAffine(img, mat, (w, h), dst=out, flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                          borderMode=cv2.BORDER_REPLICATE)


def _pixels_of(b: np.ndarray, hp: int, wp: int, out: np.ndarray | None = None) -> np.ndarray:
    """(n8y, n8x) float32 values of 8×8 blocks → (Hp, Wp), each block's value on its pixels
    (OpenCV's nearest-neighbour resize by exactly 8: the same values as two np.repeat, 3x faster),
    into ``out`` where given."""
    import cv2

    return cv2.resize(b, (wp, hp), dst=out, interpolation=cv2.INTER_NEAREST)


def _block_sums(e: np.ndarray, nby8: int, nbx8: int) -> np.ndarray:
    """(Hp, Wp) float32 → (nby8·nbx8,) float64 sums over 8×8 blocks (OpenCV's area resampling:
    block means in float32, 6× faster than a numpy reduction over strided axes)."""
    import cv2

    m = cv2.resize(np.ascontiguousarray(e, np.float32), (nbx8, nby8), interpolation=cv2.INTER_AREA)
    return m.reshape(-1).astype(np.float64) * (TB * TB)


class Estimator:
    """Costs of candidate disparities for every cell.

    Args:
        luma: (N0, Hp, Wp) luma (Y plane) of the original views, any real dtype (the input's
            own uint8/uint16 keeps it at a third of an RGB light field); used as float32.
        struct: :class:`rlfc.txstructure.Structure`.
    """

    def __init__(self, luma: np.ndarray, struct, keys_order: list):
        self.luma, self.s = luma, struct
        self.n0, self.hp, self.wp = luma.shape
        self.int_luma = luma.dtype in (np.uint8, np.uint16)     # (OpenCV takes it as it is)
        self.nby8, self.nbx8 = self.hp // TB, self.wp // TB
        self.cells = [np.asarray(v) for v in struct.cell_views]
        self.key_slot = np.full(self.n0, -1, np.int64)
        self.key_slot[keys_order] = np.arange(len(keys_order))
        warp = getattr(struct, "warp", None)          # per-view warps (rlfc.txwarp): the refinement
        self.warp_dw = None if warp is None else pair_params(warp, struct.refs)   # samples through them
        self._woff: dict = {}                         # view → _warp_blocks (cached)
        self._refs32 = None                           # reference → its float32 luma (see _ref_luma)
        self._lock = threading.Lock()                     # (guards the making of _refs32, and _sets)
        self._local = threading.local()               # (the scratch set a thread's task holds: _scratch)
        self._sets: list = []                         # (free scratch sets)

    def _y(self, v: int, out: np.ndarray) -> np.ndarray:
        """(Hp, Wp) float32 luma of view v, written to ``out``."""
        np.copyto(out, self.luma[v], casting="unsafe")
        return out

    def _ref_luma(self, k: int, out: np.ndarray) -> np.ndarray:
        """(Hp, Wp) float32 luma of reference view k: the references' (key views') float32 luma
        made once per estimator where it fits in REF_FLOAT_BYTES (each reference is read by
        every view it predicts, at every cost evaluation), else written to ``out``."""
        refs = self._refs32
        if refs is None:
            with self._lock:
                if self._refs32 is None:
                    r = self.s.refs
                    ks = np.unique(r[r >= 0]).tolist()
                    fits = len(ks) * self.hp * self.wp * 4 <= REF_FLOAT_BYTES
                    self._refs32 = {k: self._y(k, np.empty((self.hp, self.wp), np.float32)) for k in ks} if fits \
                        else {}
                refs = self._refs32
        got = refs.get(k)
        return got if got is not None else self._y(k, out)

    def _scratch(self, i: int, dtype=np.float32) -> np.ndarray:
        """The calling task's i-th (Hp, Wp) scratch array of ``dtype``, kept from call to call
        (fresh megabyte arrays each cost their pages' first-touch faults: 240 000 of them in a
        stanford_chess estimate, when each cell evaluation allocated its own). A task holds one
        set of them (:meth:`_scratch_set`); the sets outlive the threads of one evaluation."""
        bufs = getattr(self._local, "bufs", None)
        if bufs is None:                              # (a call outside a task: a set of its own)
            bufs = self._local.bufs = {}
        got = bufs.get((i, dtype))
        if got is None:
            got = bufs[i, dtype] = np.empty((self.hp, self.wp), dtype)
        return got

    @contextmanager
    def _scratch_set(self):
        """Hold one set of scratch arrays (a free one, or a new one) for the calling thread while
        a task runs; it goes back to the pool for the next task, on whatever thread that runs."""
        with self._lock:
            bufs = self._sets.pop() if self._sets else {}
        self._local.bufs = bufs
        try:
            yield
        finally:
            self._local.bufs = None
            with self._lock:
                self._sets.append(bufs)

    def _warp_blocks(self, v: int) -> tuple:
        """(oy, ox) (R, n8y, n8x) float32 pixels: view v's warp offsets to each reference per 8×8
        block (:func:`rlfc.txwarp.view_offsets` / 16; cached)."""
        got = self._woff.get(v)
        if got is None:
            oy, ox = view_offsets(self.warp_dw[v], self.nby8, self.nbx8)
            got = self._woff[v] = ((oy / 16).astype(np.float32), (ox / 16).astype(np.float32))
        return got

    def _grid(self) -> tuple[np.ndarray, np.ndarray]:
        """(Hp, Wp) float32 rows and columns of every pixel (cached; 2 × 4 bytes a pixel)."""
        if getattr(self, "_gyx", None) is None:
            gy, gx = np.indices((self.hp, self.wp), np.float32)
            self._gyx = (gy, gx)
        return self._gyx

    def _nrefs(self, m: int) -> int:
        return int((self.s.refs[self.cells[m][0]] >= 0).sum())

    def costs_global_many(self, ds, runner=None, reduce=None) -> list:
        """[(n_maps, 1 + MAX_REFS, nloc8) luma SSE of every mode at global disparity d (px per
        view step; inf for modes a cell does not have) for d in ds], the (d, cell) pairs on
        ``runner``; with ``reduce``, [reduce(those costs) for d in ds] (each d's costs made in
        one array, reused: not a fresh three megabytes per candidate)."""
        nm = len(self.cells)
        pairs = [(float(d), m) for d in ds for m in range(nm)]
        runner = runner or Runner()                 # (the serial runner: a loop here, no copies)
        h = self._handle(runner)
        parts = list(runner.map_threaded(_global_task, [(h, m, d) for d, m in pairs]))
        out = []
        c = None
        for i in range(len(ds)):
            if c is None or reduce is None:
                c = np.empty((nm, 1 + MAX_REFS, self.nby8 * self.nbx8))
            c.fill(np.inf)
            for m in range(nm):
                nr = self._nrefs(m)
                c[m, :1 + nr] = parts[i * nm + m]
                parts[i * nm + m] = None            # (each part once: its memory goes as it is used)
            out.append(c if reduce is None else reduce(c))
        return out

    def drop_handle(self) -> None:
        """Forget the runner's handle of this estimator. The serial runner's handle is the
        estimator itself: the reference cycle kept the views' luma (a third of an RGB light field)
        alive through the whole encode, until the cyclic garbage collector happened to run."""
        self._shared = None

    def _handle(self, runner):
        if getattr(self, "_shared", None) is None or self._shared[0] is not runner:
            self._shared = (runner, runner.share(self))
        return self._shared[1]

    def __setstate__(self, st):
        self.__dict__.update(st)
        self._lock = threading.Lock()
        self._local = threading.local()
        self._sets = []

    def __getstate__(self):
        st = dict(self.__dict__)
        st.pop("_shared", None)
        st.pop("_gyx", None)          # (rebuilt where needed)
        st["_refs32"] = None          # (rebuilt where needed)
        st.pop("_lock", None)
        st.pop("_local", None)
        st.pop("_sets", None)         # (the scratch sets: __setstate__ starts with none)
        st["_woff"] = {}              # (rebuilt where needed)
        return st

    def _global_cell(self, m: int, d: float) -> np.ndarray:
        """(1 + nrefs, nloc8) costs of cell m at global disparity d."""
        import cv2

        s = self.s
        views = self.cells[m]
        acc = np.zeros((1 + MAX_REFS, self.nby8 * self.nbx8))
        nr = self._nrefs(m)
        shifts = [d * (s.positions[v] - s.positions[s.refs[v, j]]) for v in views.tolist() for j in range(nr)]
        if self.int_luma and all(
                float(q).is_integer() and abs(q) < n for sh in shifts for q, n in zip(sh, (self.hp, self.wp))):
            return self._global_cell_int(views, nr, shifts, acc)
        y, yk, p, e, blend = (self._scratch(i) for i in range(5))   # (reused)
        for i, v in enumerate(views.tolist()):
            self._y(v, y)
            blend.fill(0)
            for j in range(nr):
                dy, dx = shifts[i * nr + j]
                _shift(self._y(s.refs[v, j], yk), dy, dx, p)
                acc[1 + j] += _block_sums(np.square(np.subtract(y, p, out=e), out=e), self.nby8, self.nbx8)
                # in float32 (float64 products cost 0.5-1.5 CPU-s of an encode's map estimation):
                # on a grid (whole view steps, whole-pixel candidates) the shifts are whole pixels
                # of integer luma, and their multiples of k/64 sum exactly (< 2^22 sixty-fourths)
                # (one fused pass: the same exact sums, however OpenCV rounds its product)
                cv2.scaleAdd(p, float(s.weights[v, j]) / 64.0, blend, dst=blend)
            acc[0] += _block_sums(np.square(np.subtract(y, blend, out=e), out=e), self.nby8, self.nbx8)
        return acc[:1 + nr]

    def _global_cell_int(self, views: np.ndarray, nr: int, shifts: list, acc: np.ndarray) -> np.ndarray:
        """:meth:`_global_cell` where every shift is a whole number of pixels and the luma is
        uint8/uint16: each reference shifted in its own dtype (a crop and a border copy), the
        errors and the blend made in float32 by OpenCV from the integers. The same numbers: the
        differences are integers, and the blend's terms (integers × k/64, at most 23 significant
        bits) and their sums (below 2^22 sixty-fourths) are exact however OpenCV orders or fuses
        them."""
        import cv2

        s = self.s
        p, e, blend = self._scratch(0, self.luma.dtype.type), self._scratch(0), self._scratch(1)
        for i, v in enumerate(views.tolist()):
            y = self.luma[v]
            blend.fill(0)
            for j in range(nr):
                dy, dx = (int(q) for q in shifts[i * nr + j])
                _shift(self.luma[s.refs[v, j]], dy, dx, p)
                cv2.subtract(y, p, dst=e, dtype=cv2.CV_32F)
                acc[1 + j] += _block_sums(np.square(e, out=e), self.nby8, self.nbx8)
                cv2.addWeighted(p, float(s.weights[v, j]) / 64.0, blend, 1.0, 0.0, dst=blend, dtype=cv2.CV_32F)
            cv2.subtract(y, blend, dst=e, dtype=cv2.CV_32F)
            acc[0] += _block_sums(np.square(e, out=e), self.nby8, self.nbx8)
        return acc[:1 + nr]

    def costs_maps(self, d16: np.ndarray, runner=None) -> np.ndarray:
        """(n_maps, 1 + MAX_REFS, nloc8) luma SSE of every mode for per-block disparities
        ``d16`` (n_maps, nloc8) in 1/16 px per view step (the cells on ``runner``)."""
        nm = len(self.cells)
        runner = runner or Runner()
        h = self._handle(runner)
        parts = runner.map_threaded(_maps_task, [(h, m, d16[m]) for m in range(nm)])
        out = np.full((nm, 1 + MAX_REFS, self.nby8 * self.nbx8), np.inf)
        for m in range(nm):
            out[m, :1 + self._nrefs(m)] = parts[m]
        return out

    def _maps_cell(self, m: int, d16m: np.ndarray) -> np.ndarray:
        """(1 + nrefs, nloc8) costs of cell m with per-block disparities d16m (nloc8,) in 1/16 px
        per view step: each reference warped by its block's displacement, bilinear at the same
        1/16-px positions as the decoder's predictor (OpenCV ``remap``, float: the decoder's
        integer rounding is left out of an estimate that only ranks candidates)."""
        import cv2

        s = self.s
        views = self.cells[m]
        nr = self._nrefs(m)
        acc = np.zeros((1 + nr, self.nby8 * self.nbx8))
        dblk = d16m.reshape(self.nby8, self.nbx8).astype(np.float32) / 16
        # (each block's disparity on its pixels; with warps each reference's sum is spread instead)
        dpix = _pixels_of(dblk, self.hp, self.wp, self._scratch(8)) if self.warp_dw is None else None
        gy, gx = self._grid()
        y, yk, p, e, wp, blend, mx, my = (self._scratch(i) for i in range(8))
        cols, rows = {}, {}                   # view offset Δx (Δy) → the sampling columns (rows) at it
        cap = min(OFFSET_ARRAYS, OFFSET_BYTES // (4 * self.hp * self.wp))

        def at(kept_maps: dict, off: float, base: np.ndarray, spare: np.ndarray) -> np.ndarray:
            # base + dpix·off in one pass (float32, the same values as numpy's two): made once per
            # offset (a cell's views share a few) while fewer than ``cap`` are kept per thread
            # (OFFSET_ARRAYS, within OFFSET_BYTES), past them into ``spare`` each time
            got = kept_maps.get(off)
            if got is None:
                kept = len(cols) + len(rows)
                got = cv2.scaleAdd(dpix, off, base, dst=self._scratch(9 + kept) if kept < cap else spare)
                if kept < cap:
                    kept_maps[off] = got
            return got

        for v in views.tolist():
            r = s.refs[v, :nr]
            # (integer luma as it is: OpenCV subtracts float32 samples from it in float32, the
            # same numbers as numpy's float32 difference; other dtypes converted first)
            yv = self.luma[v] if self.int_luma else self._y(v, y)
            dpos = (s.positions[v] - s.positions[r]).astype(np.float32)                # (nr, 2)
            wb = s.weights[v, :nr] / 64.0
            blend.fill(0)
            warp = None if self.warp_dw is None else self._warp_blocks(v)
            for j in range(nr):               # each reference alone, and their blend
                ox, oy = float(dpos[j, 1]), float(dpos[j, 0])
                if warp is not None:
                    # each 8×8 block's displacement plus its warp offset, as the decoder's predictor
                    # (sixteenths: the sums are exact in float32)
                    np.add(gx, _pixels_of(dblk * np.float32(ox) + warp[1][j], self.hp, self.wp), out=mx)
                    np.add(gy, _pixels_of(dblk * np.float32(oy) + warp[0][j], self.hp, self.wp), out=my)
                    cx, cy = mx, my
                else:
                    cx, cy = at(cols, ox, gx, mx), at(rows, oy, gy, my)
                cvremap.remap(self._ref_luma(int(r[j]), yk), cx, cy, cv2.INTER_LINEAR, out=p)
                cv2.subtract(yv, p, dst=e, dtype=cv2.CV_32F)
                acc[1 + j] += _block_sums(np.square(e, out=e), self.nby8, self.nbx8)
                blend += np.multiply(p, np.float32(wb[j]), out=wp)
            cv2.subtract(yv, blend, dst=e, dtype=cv2.CV_32F)
            acc[0] += _block_sums(np.square(e, out=e), self.nby8, self.nbx8)
        return acc


#: bytes of float32 reference luma an estimator keeps (the key views' luma, converted once: 9
#: key views of 512² are 9 MiB); beyond it each use converts its reference again
REF_FLOAT_BYTES = 64 << 20

#: sampling-column and -row arrays a cell evaluation keeps per thread, one per view offset (a
#: cell's views share a few: hci_antinous 80 + 80 over 24 cells), within OFFSET_BYTES per thread
#: (8 arrays of 512² views, 4 of 1024², 1 of 2048²)
OFFSET_ARRAYS = 8
OFFSET_BYTES = 16 << 20


def _global_task(est: Estimator, m: int, d: float) -> np.ndarray:
    with est._scratch_set():
        return est._global_cell(m, d)


def _maps_task(est: Estimator, m: int, d16m: np.ndarray) -> np.ndarray:
    with est._scratch_set():
        return est._maps_cell(m, d16m)
