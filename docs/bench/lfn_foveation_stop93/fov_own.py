"""Own work of the mip render vs the full render: network and occupancy net stubbed (cheap, deterministic)."""
import sys, time, importlib.util, numpy as np, torch
torch.set_num_threads(1)
import cv2; cv2.setNumThreads(1)
from formats.lfcfile import open_lfc
from lfn_stream import LfnRenderer
spec = importlib.util.spec_from_file_location('oldfov', sys.argv[1] + '/lfn_stream/foveation.py')
old = importlib.util.module_from_spec(spec); old.__package__ = 'lfn_stream'; spec.loader.exec_module(old)
def mk(path, cls=None):
    r = LfnRenderer(open_lfc(path), device='cpu')
    if cls is not None:
        r.__class__ = type('OldR', (type(r),), {k: v for k, v in cls.__dict__.items() if callable(v)})
    if len(sys.argv) > 4 and sys.argv[4] == 'stub':
        occ = r.occ
        r.occ = lambda x: (occ(x) if False else (x[:, 3] * 7 + x[:, 4] * 5))   # a cheap, deterministic "occupancy"
        r.model = lambda x, n: torch.zeros(x.shape[0], 4)
    return r
new, ro = mk(sys.argv[2]), mk(sys.argv[2], old.Foveated)
h, w = new.height, new.width
lod = new.foveation_map((w / 2, h / 2), dither=False)
rounds = int(sys.argv[3])
for v in (0, 7, 33):
    row, col = divmod(v, new.cols)
    a, b = ro.render_lod_mip(row, col, lod), new.render_lod_mip(row, col, lod)
    T = {'full': [], 'old': [], 'new': []}
    for i in range(rounds):
        for k, fn in (('full', lambda: new.render(row, col)), ('old', lambda: ro.render_lod_mip(row, col, lod)),
                      ('new', lambda: new.render_lod_mip(row, col, lod)))[::1 if i % 2 else -1]:
            t = time.process_time(); fn(); T[k].append(time.process_time() - t)
    m = {k: np.median(x) * 1e3 for k, x in T.items()}
    print(f"view {v}: full {m['full']:.1f} ms, old mip {m['old']:.1f} ({m['old']/m['full']:.3f}x), new mip {m['new']:.1f} ({m['new']/m['full']:.3f}x), new/old {m['new']/m['old']:.3f}, same pixels: {np.array_equal(a, b)}", flush=True)
