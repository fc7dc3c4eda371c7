"""End-to-end A/B in one process: tx_residual.parse_lanes swapped between the old checkout's
txparse and this one, alternated; batched decode_blocks (20 000 random requests) and whole views."""
import sys, time, importlib.util, resource, numpy as np
import rlfc.profiles.tx_residual as tr
import rlfc.txparse as new
from rlfc import RlfcDecoder
from formats import open_lfc
spec = importlib.util.spec_from_file_location('rlfc.txparse_old', sys.argv[1] + '/rlfc/txparse.py')
old = importlib.util.module_from_spec(spec); old.__package__ = 'rlfc'; spec.loader.exec_module(old)
fns = {'old': old.parse_lanes, 'new': new.parse_lanes}
rounds = int(sys.argv[2])
def flt(): return resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for path in sys.argv[3:]:
    d = RlfcDecoder(open_lfc(path)); d.decode_keys(); d.decode_maps()
    c = d.core; n = d.rows * d.cols
    rng = np.random.default_rng(0); M = 20000
    v, by, bx = rng.integers(0, n, M), rng.integers(0, d.nby, M), rng.integers(0, d.nbx, M)
    keys = set(np.flatnonzero(c.is_key).tolist()); cand = [i for i in range(n) if i not in keys]
    views = [cand[int(k)] for k in np.linspace(0, len(cand) - 1, 6).round().astype(int)]
    outs = {}
    for k in fns:
        tr.parse_lanes = fns[k]; outs[k] = d.decode_blocks(v, by, bx, threads=1)
    same = np.array_equal(outs['old'], outs['new'])
    T = {(k, w): [] for k in fns for w in ('b1', 'b2', 'view')}; F = {k: [] for k in fns}
    for r in range(rounds):
        for k in (('old', 'new') if r % 2 else ('new', 'old')):
            tr.parse_lanes = fns[k]
            f0 = flt()
            for th in (1, 2):
                t = time.perf_counter(); d.decode_blocks(v, by, bx, threads=th); T[(k, f'b{th}')].append(time.perf_counter() - t)
            F[k].append(flt() - f0)
            for i in views:
                t = time.perf_counter(); d.decode_views([i], threads=1); T[(k, 'view')].append(time.perf_counter() - t)
    med = {key: np.median(x) for key, x in T.items()}
    mp = lambda k, th: M * d.block_size ** 2 / med[(k, th)] / 1e6
    print(f"{path.split('/')[-1]:30s} batched 1 thr {mp('old','b1'):.1f} -> {mp('new','b1'):.1f} Mpix/s ({med[('new','b1')]/med[('old','b1')]:.3f}x time), "
          f"2 thr {mp('old','b2'):.1f} -> {mp('new','b2'):.1f} ({med[('new','b2')]/med[('old','b2')]:.3f}x); view {med[('old','view')]*1e3:.2f} -> {med[('new','view')]*1e3:.2f} ms "
          f"({med[('new','view')]/med[('old','view')]:.3f}x); faults per two batched calls {np.median(F['old']):.0f} -> {np.median(F['new']):.0f}; same pixels {same}", flush=True)
