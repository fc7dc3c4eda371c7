"""Would a predicted key view's residual coded as JPEG 2000 (decoded by OpenJPEG, in C) cost about
what its transform-coded rows cost? (stop 82; not adopted: 2.4x the bytes on stanford_chess)

    python j2k_residual_keys.py FILE.lfc SCENE_DIR

For each predicted key view of a 40 dB file: its prediction from the decoded earlier keys (the
decoder's own, level 1), the residual against the captured view in YCoCg-R planes, offset to
11-bit unsigned and coded as one 3-component JPEG 2000 image at rising `level`s until prediction
+ decoded residual reaches the PSNR the file's own key reaches.
"""
import sys

import imagecodecs
import numpy as np

from formats import open_lfc, read_scene
from formats.pixels import from_planes, to_planes
from rlfc import RlfcDecoder


def psnr(a, b):
    m = np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2)
    return 10 * np.log10(255.0 ** 2 / m)


path, scene = sys.argv[1], sys.argv[2]
d = RlfcDecoder(open_lfc(path))
c = d.core
c.decode_keys()
lf = read_scene(scene)
views = np.asarray(lf.views).reshape(-1, *lf.views.shape[-3:])
H, W = views.shape[1:3]
lay = c.lay
tot_ours = tot_j2k = 0
for s, k in enumerate(list(lay.keys)):
    if lay.intra[k] or k in c.img_of:
        continue
    ci = c.row_of[k]
    ours = int((c.key_end[ci] - c.key_start[ci]).sum())
    locs = np.arange(c.nby * c.nbx)
    B = c.block_size
    pred = c._reconstruct(np.full(locs.size, k), locs, 1)                 # level 1: the prediction
    pred = pred.reshape(c.nby, c.nbx, B, B, c.P).transpose(0, 2, 1, 3, 4).reshape(c.Hp, c.Wp, c.P)[:H, :W]
    dec = c.keyplanes[s].reshape(c.Hp, c.Wp, c.P)[:H, :W]
    orig = views[k]
    target = psnr(orig, from_planes(dec.astype(np.int32), orig.dtype))
    off = 1024
    Ru = (to_planes(orig).astype(np.int32) - pred.astype(np.int32) + off).astype(np.uint16)
    best = None
    for lvl in np.arange(target + 8, target + 40, 0.5):               # (level is PSNR of the 11-bit image)
        cs = imagecodecs.jpeg2k_encode(Ru, level=float(lvl), bitspersample=11)
        rec = from_planes((pred + imagecodecs.jpeg2k_decode(cs).astype(np.int32) - off).astype(np.int32), orig.dtype)
        if psnr(orig, rec) >= target:
            best = len(cs)
            break
    tot_ours += ours
    tot_j2k += best if best else np.nan
    print(f"key {k}: transform rows {ours} B at {target:.2f} dB; JPEG 2000 residual {best} B")
print("total", tot_ours, tot_j2k, "ratio %.2f" % (tot_j2k / tot_ours))
