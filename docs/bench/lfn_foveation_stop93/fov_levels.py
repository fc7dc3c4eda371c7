import sys, time, torch
torch.set_num_threads(1)
from formats.lfcfile import open_lfc
from lfn_stream import LfnRenderer
r = LfnRenderer(open_lfc(sys.argv[1]), device='cpu')
h, w = r.height, r.width
orig = r.render_rays
log = []
def rr(rays, neurons, batch=None, use_occupancy=True):
    n0 = r.rays_evaluated
    t = time.perf_counter(); out = orig(rays, neurons, batch, use_occupancy); dt = time.perf_counter() - t
    log.append((rays.shape[0], r.rays_evaluated - n0, neurons, use_occupancy, dt * 1e3)); return out
r.render_rays = rr
for v in [int(x) for x in sys.argv[2].split(',')]:
    row, col = divmod(v, r.cols)
    lod = r.foveation_map((w / 2, h / 2), dither=False)
    for name, fn in (('full', lambda: r.render(row, col)), ('mip', lambda: r.render_lod_mip(row, col, lod))):
        fn(); log.clear(); t = time.perf_counter(); fn(); T = (time.perf_counter() - t) * 1e3
        print(v, name, 'total %.1f ms' % T, 'calls:', [(a, b, round(c, 1), d, round(e, 1)) for a, b, c, d, e in log])
