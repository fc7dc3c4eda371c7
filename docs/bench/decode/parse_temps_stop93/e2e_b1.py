import sys, time, importlib.util, numpy as np
import rlfc.profiles.tx_residual as tr
import rlfc.txparse as new
from rlfc import RlfcDecoder
from formats import open_lfc
spec = importlib.util.spec_from_file_location('rlfc.txparse_old', sys.argv[1] + '/rlfc/txparse.py')
old = importlib.util.module_from_spec(spec); old.__package__ = 'rlfc'; spec.loader.exec_module(old)
fns = {'old': old.parse_lanes, 'new': new.parse_lanes}
d = RlfcDecoder(open_lfc(sys.argv[3])); d.decode_keys(); d.decode_maps()
n = d.rows * d.cols; rng = np.random.default_rng(0); M = 20000
v, by, bx = rng.integers(0, n, M), rng.integers(0, d.nby, M), rng.integers(0, d.nbx, M)
T = {k: [] for k in fns}
for r in range(int(sys.argv[2])):
    for k in (('old', 'new') if r % 2 else ('new', 'old')):
        tr.parse_lanes = fns[k]
        t = time.process_time(); d.decode_blocks(v, by, bx, threads=1); T[k].append(time.process_time() - t)
print({k: [round(x * 1e3) for x in sorted(T[k])] for k in T}, 'median new/old %.3f' % (np.median(T['new']) / np.median(T['old'])))
