"""A first frame's parses (captured), then parse_lanes of OLD and of this checkout on them, alternated."""
import sys, time, importlib.util, numpy as np
import rlfc.profiles.tx_residual as tr
import rlfc.txparse as new
from rlfc import RlfcDecoder
from formats import open_lfc
spec = importlib.util.spec_from_file_location('rlfc.txparse_old', sys.argv[1] + '/rlfc/txparse.py')
old = importlib.util.module_from_spec(spec); old.__package__ = 'rlfc'; spec.loader.exec_module(old)
cap = []
orig = tr.parse_lanes
def spy(*a, **k):
    cap.append(a); return orig(*a, **k)
tr.parse_lanes = spy
for path in sys.argv[3:]:
    cap.clear()
    d = RlfcDecoder(open_lfc(path))
    ren = d.renderer(cache_mib=1024)
    ren.render((d.rows - 1) / 2, (d.cols - 1) / 2 + min(d.rows, d.cols) / 3)
    tr.parse_lanes = orig
    for i, a in enumerate(cap):
        A, B = old.parse_lanes(*a), new.parse_lanes(*a)
        same = np.array_equal(A.modes, B.modes) and np.array_equal(A.index, B.index) and np.array_equal(A.values, B.values)
        T = {'old': [], 'new': []}
        for r in range(int(sys.argv[2])):
            for k, m in ((('old', old), ('new', new)) if r % 2 else (('new', new), ('old', old))):
                t = time.perf_counter(); m.parse_lanes(*a); T[k].append(time.perf_counter() - t)
        o, nn = np.median(T['old']) * 1e3, np.median(T['new']) * 1e3
        print(f"{path.split('/')[-1]:30s} parse {i}: {a[1].size} lanes, old {o:.2f} ms new {nn:.2f} ms ({nn / o:.3f}x) same {same}", flush=True)
    tr.parse_lanes = spy
