"""The RLFC decoder: full light field, one view, one block (random access), many blocks
(batched), each at any progressive level, for every profile.

The header is validated once at open (:mod:`rlfc.header`); the profile (found by the id in
the file) reconstructs planes; this module turns planes into pixels and checks requests. The
file stays compressed (memory-mapped or behind a byte-range source).
"""
from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from formats.codec_api import Decoder, check_integers, check_view_indices
from formats.errors import ParameterError
from formats.lfcfile import LfcFile, check_codec_version
from formats.limits import DEFAULT
from formats.pixels import from_planes

from .header import CODEC_ID, CODEC_VERSION, RlfcHeader
from .profiles import get_profile


DECODE_CHUNK = 1 << 19      # pixels per chunk of a batched call (its temporaries stay in the caches)


def default_threads() -> int:
    """Threads a decoder uses by default: the cores this process may run on, at most 4."""
    try:
        n = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        n = os.cpu_count() or 1
    return max(1, min(4, n))


class RlfcDecoder(Decoder):
    """Decoder over an opened .lfc file.

    Attributes:
        rows, cols, height, width, channels, dtype: the light field's geometry.
        block_size: B; nby, nbx: blocks per column and row. levels: the coarsest progressive
            level (valid ``level`` arguments are 0..levels). profile: the file's profile id.
        threads: threads of batched and whole-view decodes (default :func:`default_threads`;
            profiles that are not thread-safe use one).
        core: the profile's planes decoder.
    """

    def __init__(self, f: LfcFile, *, limits=None, threads: int | None = None):
        check_codec_version(f, CODEC_ID, CODEC_VERSION)
        self.threads = 1
        self.threads = self._threads(default_threads() if threads is None else threads)
        self.file = f
        # the caller's limits, else those the file was opened with (as the LFN renderer): header,
        # profile and requests are all checked against the same caps
        self.limits = limits or getattr(f, "limits", None) or DEFAULT
        hdr, cfg = RlfcHeader.read(f.full_meta(), f.container.name, self.limits)
        self.header, self.profile = hdr, hdr.profile
        self.core = get_profile(hdr.profile).open(f.container, hdr, cfg, self.limits)
        self.rows, self.cols = hdr.rows, hdr.cols
        self.height, self.width, self.channels, self.dtype = hdr.height, hdr.width, hdr.channels, hdr.dtype
        self.P = hdr.planes
        self.block_size = hdr.block_size
        self.Hp, self.Wp = hdr.padded
        self.nby, self.nbx = hdr.blocks
        self.levels = self.core.levels

    # -- requests ---------------------------------------------------------------------------
    def requests(self, views, by, bx) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Batched (view, block row, block column) requests as int64 arrays, range-checked."""
        try:
            views, by, bx = (np.asarray(a).reshape(-1) for a in (views, by, bx))
        except (TypeError, ValueError):
            raise ParameterError("block requests must be integer arrays") from None
        if not (views.shape == by.shape == bx.shape):
            raise ParameterError(f"views, by and bx must have the same length ({views.size}, {by.size}, {bx.size})")
        if any(a.size and a.dtype.kind not in "iu" for a in (views, by, bx)):
            raise ParameterError("block requests must be integers")
        cap = self.limits.max_scene_pixels // self.block_size ** 2
        if views.size > cap:          # checked before any request-sized array is made
            raise ParameterError(f"{views.size} block requests would decode {views.size * self.block_size ** 2} "
                                 f"pixels, over the {self.limits.max_scene_pixels} one call may return "
                                 f"(Limits.max_scene_pixels): request at most {cap} blocks per call")
        views, by, bx = (a.astype(np.int64) for a in (views, by, bx))
        if views.size and (views.min() < 0 or views.max() >= self.rows * self.cols):
            raise ParameterError(f"view index out of range (0..{self.rows * self.cols - 1})")
        if by.size and (by.min() < 0 or by.max() >= self.nby or bx.min() < 0 or bx.max() >= self.nbx):
            raise ParameterError(f"block index out of range (blocks are {self.nby} rows x {self.nbx} cols of "
                                 f"{self.block_size} px)")
        return views, by, bx

    def check_level(self, level) -> int:
        if type(level) is int and 0 <= level <= self.levels:     # (the common case, without the checks' calls)
            return level
        if isinstance(level, bool) or not isinstance(level, (int, np.integer, float, np.floating)) \
                or not np.isfinite(level) or level != int(level) or not 0 <= int(level) <= self.levels:
            raise ParameterError(f"level must be an integer within 0..{self.levels} (0 = full quality, "
                                 f"{self.levels} = coarsest), got {level!r}")
        return int(level)

    def view_index(self, row: int, col: int) -> int:
        if type(row) is not int or type(col) is not int:        # (plain ints: no call)
            check_integers(row=row, col=col)
        if not (0 <= row < self.rows and 0 <= col < self.cols):
            raise ParameterError(f"view ({row},{col}) is outside the {self.rows}x{self.cols} grid")
        return row * self.cols + col

    # -- decoders ---------------------------------------------------------------------------
    def decode_blocks(self, views, by, bx, level: int = 0, planes: bool = False, threads: int | None = None
                      ) -> np.ndarray:
        """Batched random access: many (view, block) requests, vectorized in chunks of about
        ``DECODE_CHUNK`` pixels (requests of one view together), the chunks on ``threads``
        threads (default: the decoder's ``threads``).

        Args:
            views: (M,) flat view indices (row·cols + col); by, bx: (M,) block indices.
            level: progressive level (0 = full quality .. ``levels``).
            planes: return int32 YCoCg-R planes instead of pixels.
            threads: threads for this call (1 = this thread only).

        Returns:
            (M, B, B, C) pixels (uint8/uint16; blocks past the image edge hold padding).
        """
        level = self.check_level(level)
        views, by, bx = self.requests(views, by, bx)
        threads = self._threads(threads)
        self.file.container.check_unchanged()
        B, M = self.block_size, views.size
        out = np.empty((M, B, B, self.P if planes else self.channels), np.int32 if planes else self.dtype)
        self.core.prepare(views, by)
        order = np.lexsort((bx, by, views))           # requests of one view together: shared references
        step = max(1, DECODE_CHUNK // (B * B))
        pre = getattr(self.core, "preparse", None)    # (a profile that parses the chunks' streams ahead)
        ahead = pre(views[order], by[order], bx[order], level) if pre is not None and M > step else None

        to_pixels = not planes and getattr(self.core, "blocks_to_pixels", False)

        def run(a: int) -> None:
            i = order[a:a + step]
            kw = {} if ahead is None else {"ahead": ahead, "first": a}
            if to_pixels:                             # (the profile converts before assembling its blocks)
                kw["pixels"] = self.dtype
            acc = self.core.blocks(views[i], by[i], bx[i], level, **kw).reshape(i.size, B, B, self.P)
            out[i] = acc if planes or to_pixels else from_planes(acc, self.dtype)

        self._run(run, range(0, M, step), threads)
        return out

    def _run(self, fn, items, threads: int) -> None:
        """``fn(item)`` for each item: on a pool of ``threads`` threads where the profile allows
        it (numpy and OpenCV release the GIL), else in this thread."""
        if threads > 1 and len(items) > 1 and getattr(self.core, "threads_ok", False):
            with ThreadPoolExecutor(threads) as pool:
                list(pool.map(fn, items))
        else:
            for x in items:
                fn(x)

    def _threads(self, threads) -> int:
        t = self.threads if threads is None else threads
        if isinstance(t, bool) or not isinstance(t, (int, np.integer)) or not 1 <= t <= 256:
            raise ParameterError(f"threads must be an integer within 1..256, got {t!r}")
        return int(t)

    def decode_block(self, row: int, col: int, by: int, bx: int, level: int = 0) -> np.ndarray:
        """One block of one view: (b_h, b_w, C) pixels, cropped at the image edges.

        Block (by, bx) covers pixels [by·B, (by+1)·B) × [bx·B, (bx+1)·B).
        """
        v = self.view_index(row, col)
        if type(by) is not int or type(bx) is not int:
            check_integers(by=by, bx=bx)
        if not (0 <= by < self.nby and 0 <= bx < self.nbx):
            raise ParameterError(f"block ({by},{bx}) is outside the {self.nby}x{self.nbx} block grid "
                                 f"({self.height}x{self.width} px, B={self.block_size})")
        level = self.check_level(level)
        c = self.file.container           # (a profile that checks each read it makes skips the stat here:
        c.check_open() if self.core.reads_checked else c.check_unchanged()   # a block held in memory reads none)
        B = self.block_size
        lean = getattr(self.core, "block_pixels", None)      # a profile's one-request pixel path, where it has one
        out = lean(v, int(by), int(bx), level) if lean is not None else None
        if out is None:
            out = from_planes(self.core.block(v, int(by), int(bx), level).reshape(B, B, self.P), self.dtype)
        if (by + 1) * B <= self.height and (bx + 1) * B <= self.width:
            return out                    # (a block inside the image: nothing to crop)
        return out[:min(B, self.height - by * B), :min(B, self.width - bx * B)]

    def decode_views(self, views=None, level: int = 0, planes: bool = False, threads: int | None = None
                     ) -> np.ndarray:
        """Decode whole views (flat indices; None = all) at a progressive level, in the groups
        the profile asks for (on ``threads`` threads; default: the decoder's ``threads``); views
        the profile decodes straight to pixels (``image_views``: whole JPEG 2000 images no view
        is predicted from, e.g. a posed capture's) skip the planes unless ``planes`` is asked.

        Returns:
            (n, H, W, C) pixels (or int32 planes with ``planes=True``), cropped to the image.
        """
        level = self.check_level(level)
        if views is None:
            views = np.arange(self.rows * self.cols)
        else:
            views = check_view_indices(views, self.rows * self.cols)
        threads = self._threads(threads)
        self.file.container.check_unchanged()
        H, W = self.height, self.width
        out = np.empty((views.size, H, W, self.P if planes else self.channels), np.int32 if planes else self.dtype)
        # views the profile decodes straight to pixels (whole images no view is predicted from,
        # e.g. a posed capture's JPEG 2000 views): each on its own, OpenJPEG's threads with it alone
        direct = getattr(self.core, "image_views", None)
        is_img = direct(views) if direct is not None and not planes else np.zeros(views.size, bool)
        img = np.flatnonzero(is_img)
        if img.size:
            def one(j: int) -> None:
                out[j] = self.core.image_pixels(int(views[j]), threads if img.size == 1 else 1)[:H, :W]

            self._run(one, img.tolist(), threads)
        rest = np.flatnonzero(~is_img)       # (not setdiff1d: its np.unique imports numpy.ma, 9 ms, on a first call)
        if not rest.size:
            return out
        groups = self.core.view_groups(views[rest])    # views whose streams are parsed together
        starts = np.concatenate([[0], np.cumsum([g.size for g in groups])])

        def run(i: int) -> None:
            p = self.core.views(groups[i], level)[:, :H, :W]
            at = rest[starts[i]:starts[i + 1]]
            if at.size == at[-1] - at[0] + 1:          # (consecutive: a slice, no fancy-index copy)
                at = slice(int(at[0]), int(at[-1]) + 1)
            out[at] = p if planes else from_planes(p, self.dtype)

        self._run(run, range(len(groups)), threads)
        return out

    def decode_keys(self) -> None:
        """Decode every key view now. ``tx`` files decode key views by block rows when a
        request first needs them (opening is fast, a first block needs about a fifth of them);
        a renderer about to sweep the whole light field can pay the whole decode once, up front,
        instead of in pieces over its first frames. Other profiles decode them at open."""
        getattr(self.core, "decode_keys", lambda: None)()

    def decode_maps(self) -> None:
        """Decode every view's disparity map now, with each view's constants of single-block
        requests. ``tx`` files decode a map when a request first needs it (a few ms each); after
        :meth:`decode_keys` and this, a request costs only its own block (hci_antinous, 2 000
        random single blocks: p99 104 → 65 µs, worst 2.9 → 0.14 ms). Other profiles decode them
        at open."""
        getattr(self.core, "decode_maps", lambda: None)()

    def decode_view(self, row: int, col: int, level: int = 0) -> np.ndarray:
        """One view: (H, W, C) pixels."""
        return self.decode_views([self.view_index(row, col)], level)[0]

    def decode_all(self, level: int = 0, threads: int | None = None) -> np.ndarray:
        """The whole light field: (rows, cols, H, W, C) pixels."""
        out = self.decode_views(None, level, threads=threads)
        return out.reshape(self.rows, self.cols, *out.shape[1:])

    def renderer(self, **kw):
        """A :class:`rlfc.render.Renderer` of novel views over this decoder (grid files)."""
        from .render import Renderer

        return Renderer(self, **kw)

    def info(self) -> dict:
        core = self.core.info()
        summary = (f"RLFC profile {self.profile}, {self.block_size}x{self.block_size}-px blocks, levels "
                   f"0..{self.levels} (0 = full quality)")
        if core.get("warped_views"):
            summary += f"; {core['warped_views']} views predicted through per-view warps (--warps)"
        if core.get("jpeg2000_views"):
            n = core["jpeg2000_views"]
            summary += f"; {n} view{'s' if n > 1 else ''} coded alone as JPEG 2000"
            if core.get("alpha_stream_bytes"):
                summary += f" (their colour; alpha exact, {core['alpha_stream_bytes']} bytes of alpha streams)"
        return {"codec": CODEC_ID, "profile": self.profile, "levels": self.levels, "block_size": self.block_size,
                "summary": summary, **core}
