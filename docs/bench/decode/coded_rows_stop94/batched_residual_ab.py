import sys, time, numpy as np, rlfc
from formats import open_lfc
from rlfc.transform import inverse_interleaved, ZIGZAG
from rlfc.profiles.tx_single import _dequantize_clipped
for path in sys.argv[1:]:
    d = rlfc.RlfcDecoder(open_lfc(path)); c = d.core
    rng = np.random.default_rng(0); M = 20000; n = d.rows * d.cols
    v, by, bx = rng.integers(0, n, M), rng.integers(0, d.nby, M), rng.integers(0, d.nbx, M)
    loc = by * c.nbx + bx
    have = np.flatnonzero(~c.is_key[v] & c.coded[v, loc])[:4096]
    views, locs = v[have], loc[have]
    parsed = c._parse(views, locs)
    P, nt = c.P, c.nt
    step = np.asarray(c.lay.step16, np.int64)          # (2, P)
    assert not c.lay.bypass.any()
    def inter(views, parsed):
        idx, q = parsed.index, parsed.values
        blk, pos = idx >> 6, idx & 63
        plane = blk % P
        q16 = step[1][plane] if not c.is_key[views].any() else step[np.where(c.is_key[views[blk // (nt * P)]], 0, 1), plane]
        deq = _dequantize_clipped(q, q16)
        X = np.zeros((views.size * nt, 8, 8 * P))
        X.reshape(-1)[(blk // P) * (64 * P) + ZIGZAG[pos] * P + plane] = deq
        R = inverse_interleaved(X, P)
        return R.astype(np.int32).reshape(views.size, nt, 8, 8, P)
    a = c._residual(views, parsed); b = inter(views, parsed)
    print('same', np.array_equal(a, b), a.shape, parsed.index.size, 'coefs')
    T = {'cur': [], 'inter': []}
    for r in range(9):
        for k, f in ((('cur', c._residual), ('inter', inter)) if r % 2 else (('inter', inter), ('cur', c._residual))):
            t = time.perf_counter(); f(views, parsed); T[k].append(time.perf_counter() - t)
    o, w = np.median(T['cur']) * 1e3, np.median(T['inter']) * 1e3
    print(f"{path.split('/')[-1]:30s} _residual 4096 lanes: current {o:.2f} ms interleaved {w:.2f} ms ({w/o:.3f})")
