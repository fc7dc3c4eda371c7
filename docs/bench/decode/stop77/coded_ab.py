"""old vs new coded single blocks (their residual rows): two decoders of one file, the old one's
core running the old TxDecoder (OLD checkout); the same pixels checked; requests alternated."""
import sys, os, time, types
os.environ["OMP_NUM_THREADS"] = "1"
sys.path.insert(0, "/work/main")
import numpy as np
from formats.lfcfile import open_lfc
from rlfc import RlfcDecoder
import rlfc.profiles.tx  # noqa: F401
OLD = os.environ.get("OLD", "/tmp/old77b")
ots = types.ModuleType("rlfc._old_txsample"); ots.__package__ = "rlfc"; sys.modules[ots.__name__] = ots
exec(compile(open(OLD + "/rlfc/txsample.py").read(), "old_txsample", "exec"), ots.__dict__)
otx = types.ModuleType("rlfc.profiles._old_tx"); otx.__package__ = "rlfc.profiles"; sys.modules[otx.__name__] = otx
exec(compile(open(OLD + "/rlfc/profiles/tx.py").read().replace("from ..txsample import", "from .._old_txsample import"),
             "old_tx", "exec"), otx.__dict__)
for path in sys.argv[1:]:
    dn = RlfcDecoder(open_lfc(path)); do = RlfcDecoder(open_lfc(path)); do.core.__class__ = otx.TxDecoder
    for d in (dn, do):
        d.core.decode_keys(); d.core.decode_maps()
    c = dn.core
    cand = np.argwhere(c.coded & ~c.is_key[:, None])
    if len(cand) == 0:
        print(os.path.basename(path), 'no coded block in a view with references'); continue
    rng = np.random.default_rng(1)
    req = []
    for i in rng.choice(len(cand), min(1500, len(cand)), replace=False):
        v, loc = cand[i]; by, bx = divmod(int(loc), c.nbx)
        req.append((int(v) // dn.cols, int(v) % dn.cols, by, bx))
    for r in req:
        assert np.array_equal(do.decode_block(*r), dn.decode_block(*r)), r
    T = {"old": [], "new": []}
    pc = time.perf_counter
    for rnd in range(4):
        for i, r in enumerate(req):
            for k, d in ((("old", do), ("new", dn)) if (i + rnd) % 2 == 0 else (("new", dn), ("old", do))):
                t = pc(); d.decode_block(*r); T[k].append(pc() - t)
    o, n = (np.percentile(np.array(T[k]) * 1e6, [50, 90, 99]) for k in ("old", "new"))
    print(os.path.basename(path), len(req), "coded blocks, the same pixels; p50/p90/p99 µs: old %.1f/%.1f/%.1f new %.1f/%.1f/%.1f (p50 %.3f)" % (*o, *n, n[0] / o[0]), flush=True)
