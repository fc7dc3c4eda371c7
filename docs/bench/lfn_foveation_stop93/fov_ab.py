"""In-process A/B of the mip render: old (a checkout's lfn_stream.foveation) vs new, alternated."""
import sys, time, importlib.util, numpy as np, torch
torch.set_num_threads(1)
from formats.lfcfile import open_lfc
from lfn_stream import LfnRenderer
spec = importlib.util.spec_from_file_location('oldfov', sys.argv[1] + '/lfn_stream/foveation.py', submodule_search_locations=None)
old = importlib.util.module_from_spec(spec); old.__package__ = 'lfn_stream'; spec.loader.exec_module(old)
r = LfnRenderer(open_lfc(sys.argv[2]), device='cpu')
views = [int(v) for v in sys.argv[3].split(',')]; rounds = int(sys.argv[4])
h, w = r.height, r.width
lod = r.foveation_map((w / 2, h / 2), dither=False)
# bind the old class's methods on a copy of the renderer's class
Old = type('OldR', (type(r),), {k: v for k, v in old.Foveated.__dict__.items() if callable(v) or isinstance(v, (staticmethod, classmethod))})
ro = LfnRenderer(open_lfc(sys.argv[2]), device='cpu'); ro.__class__ = Old
for v in views:
    row, col = divmod(v, r.cols)
    a = ro.render_lod_mip(row, col, lod); b = r.render_lod_mip(row, col, lod)
    diff = float(np.abs(a - b).max())
    T = {'full': [], 'old': [], 'new': []}
    for i in range(rounds):
        for k, fn in (('full', lambda: r.render(row, col)), ('old', lambda: ro.render_lod_mip(row, col, lod)), ('new', lambda: r.render_lod_mip(row, col, lod)))[::1 if i % 2 else -1]:
            t = time.perf_counter(); fn(); T[k].append(time.perf_counter() - t)
    m = {k: np.median(x) * 1e3 for k, x in T.items()}
    print(f"view {v}: full {m['full']:.1f} ms, old mip {m['old']:.1f} ({m['old']/m['full']:.3f}x), new mip {m['new']:.1f} ({m['new']/m['full']:.3f}x), new/old {m['new']/m['old']:.3f}, max |diff| {diff:.2e}", flush=True)
