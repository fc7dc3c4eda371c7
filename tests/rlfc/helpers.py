import numpy as np

import rlfc.decoder as rdec

from formats.container import build_container
from formats.lfcfile import encode_meta, open_lfc
from formats.lightfield import LightField, grid_positions
from rlfc import RlfcDecoder, RlfcParams, encode_with_params


def make_lf(views, layout="grid"):
    r, c = views.shape[:2]
    return LightField(views=views, positions=grid_positions(r, c), layout=layout)


def posed_lf(views):
    """(n, H, W, C) views as a posed capture (one row, every view an intra key for tx)."""
    return make_lf(np.ascontiguousarray(views)[None], layout="posed")


def roundtrip(lf, params=None):
    """Encode in memory, reopen, return (decoder, nbytes, loop result)."""
    params = params or RlfcParams()
    cfg, sections, loop = encode_with_params(lf, params)
    blob = b"".join(bytes(p) for p in build_container(encode_meta("rlfc", 1, cfg, lf.geometry()), sections))
    return RlfcDecoder(open_lfc(blob)), len(blob), loop


def smooth_lf(rows=3, cols=4, h=20, w=28, c=3, dtype=np.uint8, seed=0):
    """A synthetic light field with parallax: a textured plane shifting 1 px per view."""
    rng = np.random.default_rng(seed)
    peak = np.iinfo(dtype).max
    base = rng.random((h + 2 * rows + 4, w + 2 * cols + 4, c))
    k = np.ones(5) / 5
    for ax in (0, 1):
        base = np.apply_along_axis(lambda m: np.convolve(m, k, mode="same"), ax, base)
    base = (base - base.min()) / (np.ptp(base) + 1e-9)
    views = np.zeros((rows, cols, h, w, c), dtype=dtype)
    for r in range(rows):
        for cc in range(cols):
            views[r, cc] = np.rint(base[r:r + h, cc:cc + w] * peak).astype(dtype)
    return make_lf(views)


def check_agreement(d, lf_views_shape):
    """Full decode == per-view == single blocks == batched blocks, at every level."""
    rows, cols = d.rows, d.cols
    B = d.block_size
    for level in range(d.levels + 1):
        full = d.decode_all(level)
        assert full.shape == lf_views_shape
        v = (rows - 1, cols - 1)
        assert (d.decode_view(*v, level=level) == full[v]).all()
        views = np.repeat(np.arange(rows * cols), d.nby * d.nbx)
        by = np.tile(np.repeat(np.arange(d.nby), d.nbx), rows * cols)
        bx = np.tile(np.tile(np.arange(d.nbx), d.nby), rows * cols)
        blocks = d.decode_blocks(views, by, bx, level)
        H, W = d.height, d.width
        for i in np.linspace(0, len(views) - 1, min(len(views), 25)).astype(int):
            r, c = divmod(int(views[i]), cols)
            ref = full[r, c, by[i] * B:(by[i] + 1) * B, bx[i] * B:(bx[i] + 1) * B]
            one = d.decode_block(r, c, int(by[i]), int(bx[i]), level)
            assert one.shape == ref.shape and (one == ref).all()
            assert (blocks[i][:ref.shape[0], :ref.shape[1]] == ref).all()
        # every block of the batch against the full decode, reassembled
        img = blocks.reshape(rows * cols, d.nby, d.nbx, B, B, -1).transpose(0, 1, 3, 2, 4, 5)
        img = img.reshape(rows, cols, d.nby * B, d.nbx * B, -1)[:, :, :H, :W]
        assert (img == full).all()
        # chunked and threaded batches, threaded whole views: the same pixels
        old = rdec.DECODE_CHUNK
        try:
            rdec.DECODE_CHUNK = B * B * 7                   # 7 requests per chunk
            for th in (1, 3):
                assert (d.decode_blocks(views[::-1], by[::-1], bx[::-1], level, threads=th) == blocks[::-1]).all()
        finally:
            rdec.DECODE_CHUNK = old
        assert (d.decode_all(level, threads=3) == full).all()


def open_encoded(lf, enc):
    """(decoder, file bytes) of an Encoded (any RLFC profile), built in memory."""
    blob = b"".join(bytes(p) for p in build_container(encode_meta("rlfc", 1, enc.config, lf.geometry()), enc.sections))
    return RlfcDecoder(open_lfc(blob)), blob
