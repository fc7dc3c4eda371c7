"""In-process A/B of a single coded request (``decode_block``): the old checkout's one-request
residual path (``SingleRequests.block_pixels``, ``_residual_rows``, ``parse_one``, loaded from
OLD and bound to a second decoder of the same file) against this checkout's, alternated in
rounds; the pixels compared. Usage: python single_ab.py OLD ROUNDS FILE.lfc ...
"""
import importlib.util
import sys
import time
import types

import numpy as np

import rlfc.profiles.tx_single  # noqa: F401  (the package's modules first)
from formats import open_lfc
from rlfc import RlfcDecoder


def load(path, name, package):
    spec = importlib.util.spec_from_file_location(name, path)
    m = importlib.util.module_from_spec(spec)
    m.__package__ = package
    spec.loader.exec_module(m)
    return m


old_root, rounds = sys.argv[1], int(sys.argv[2])
old_p1 = load(old_root + "/rlfc/txparse_one.py", "rlfc.txparse_one_old", "rlfc")
old_ts = load(old_root + "/rlfc/profiles/tx_single.py", "rlfc.profiles.tx_single_old", "rlfc.profiles")
old_ts.parse_one = old_p1.parse_one


def as_old(d):
    c = d.core
    for name in ("block_pixels", "_residual_rows", "_res_tables", "_parse_one"):
        setattr(c, name, types.MethodType(getattr(old_ts.SingleRequests, name), c))
    return d


def median_us(d, reqs):
    t = []
    for r, c, by, bx in reqs:
        t0 = time.perf_counter()
        d.decode_block(r, c, by, bx)
        t.append(time.perf_counter() - t0)
    return np.median(t) * 1e6, np.percentile(t, 99) * 1e6


for path in sys.argv[3:]:
    new, old = RlfcDecoder(open_lfc(path)), as_old(RlfcDecoder(open_lfc(path)))
    for d in (new, old):
        d.decode_keys()
        d.decode_maps()
    core = new.core
    rng = np.random.default_rng(0)
    n = new.rows * new.cols
    v, by, bx = rng.integers(0, n, 6000), rng.integers(0, new.nby, 6000), rng.integers(0, new.nbx, 6000)
    loc = by * new.nbx + bx
    coded = np.flatnonzero(~core.is_key[v] & core.coded[v, loc])[:600]
    sets = {"coded": [(*divmod(int(v[i]), new.cols), int(by[i]), int(bx[i])) for i in coded],
            "random": [(*divmod(int(v[i]), new.cols), int(by[i]), int(bx[i])) for i in range(1500)]}
    same = all((new.decode_block(*q) == old.decode_block(*q)).all() for q in sets["coded"] + sets["random"])
    for name, reqs in sets.items():
        if not reqs:
            continue
        R = {"old": [], "new": []}
        for i in range(rounds):
            for k, d in ((("old", old), ("new", new)) if i % 2 else (("new", new), ("old", old))):
                R[k].append(median_us(d, reqs))
        o, w = np.median(R["old"], axis=0), np.median(R["new"], axis=0)
        print(f"{path.split('/')[-1]:30s} {name:6s} n {len(reqs):4d}: p50 old {o[0]:6.1f} new {w[0]:6.1f} µs "
              f"({w[0] / o[0]:.3f}); p99 old {o[1]:6.1f} new {w[1]:6.1f} ({w[1] / o[1]:.3f}); same pixels {same}",
              flush=True)
