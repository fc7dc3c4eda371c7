"""In-process A/B of parse_lanes: old checkout's rlfc.txparse vs this one, same streams; equality + time."""
import sys, time, importlib.util, resource, numpy as np
from rlfc import RlfcDecoder
from formats import open_lfc
import rlfc.txparse as new
spec = importlib.util.spec_from_file_location('rlfc.txparse_old', sys.argv[1] + '/rlfc/txparse.py')
old = importlib.util.module_from_spec(spec); old.__package__ = 'rlfc'; spec.loader.exec_module(old)
rounds = int(sys.argv[2])
import os
if os.environ.get("KEEP"): from formats.heap import keep_freed; print("keep_freed", keep_freed())
for path in sys.argv[3:]:
    d = RlfcDecoder(open_lfc(path)); c = d.core
    rng = np.random.default_rng(0)
    n = d.rows * d.cols
    M = 20000
    v, by, bx = rng.integers(0, n, M), rng.integers(0, d.nby, M), rng.integers(0, d.nbx, M)
    loc = by * c.nbx + bx
    have = np.flatnonzero(~c.is_key[v] & c.coded[v, loc])
    cases = {'4096 random': (v[have][:4096], loc[have][:4096])}
    keys = set(np.flatnonzero(c.is_key).tolist())
    nk = [i for i in range(n) if i not in keys]
    vv = nk[len(nk) // 2]
    l1 = np.flatnonzero(c.coded[vv]); cases['one view'] = (np.full(l1.size, vv), l1)
    # key rows of the centre key (every block of a key row is coded)
    kk = sorted(keys)[len(keys) // 2]
    lk = np.flatnonzero(c.coded[kk]); cases['one key view'] = (np.full(lk.size, kk), lk)
    for name, (vs, ls) in cases.items():
        if vs.size < 2:
            continue
        s, e = c.start[vs, ls], c.end[vs, ls]
        buf, s2, e2 = c._streams(s, e)
        kind = c.lay.intra[vs].astype(np.int64); key = c.is_key[vs].astype(np.int64)
        args = (buf, s2, e2, c.tables, c.nt, c.pcs, kind, key, 'x')
        a, b = old.parse_lanes(*args), new.parse_lanes(*args)
        same = np.array_equal(a.modes, b.modes) and np.array_equal(a.index, b.index) and np.array_equal(a.values, b.values)
        T = {'old': [], 'new': []}; F = {'old': [], 'new': []}
        for i in range(rounds):
            for k, m in ((('old', old), ('new', new)) if i % 2 else (('new', new), ('old', old))):
                f0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
                t = time.perf_counter(); m.parse_lanes(*args); T[k].append(time.perf_counter() - t)
                F[k].append(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - f0)
        mo, mn = np.median(T['old']) * 1e3, np.median(T['new']) * 1e3
        print(f"{path.split('/')[-1]:32s} {name:13s} lanes {vs.size:5d}: old {mo:7.2f} ms new {mn:7.2f} ms  new/old {mn / mo:.3f}  same {same}  faults old {np.median(F['old']):.0f} new {np.median(F['new']):.0f}", flush=True)
