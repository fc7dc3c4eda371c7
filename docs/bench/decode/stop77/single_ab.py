"""old vs new single-block decode: two decoders of one file, the old one's core running the old
TxDecoder and txsample code; requests alternated one by one (drift cancels). OLD = old checkout."""
import sys, os, time, types, hashlib
os.environ["OMP_NUM_THREADS"] = "1"
sys.path.insert(0, "/work/main")
import numpy as np
from formats.lfcfile import open_lfc
from rlfc import RlfcDecoder
import rlfc.profiles.tx  # noqa: F401  (the new modules first)
OLD = os.environ.get("OLD", "/tmp/oldF")
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
    rng = np.random.default_rng(1)
    req = [(int(rng.integers(0, dn.rows)), int(rng.integers(0, dn.cols)), int(rng.integers(0, dn.nby)), int(rng.integers(0, dn.nbx))) for _ in range(12000)]
    req = [r for r in req if not c.is_key[r[0] * dn.cols + r[1]]]
    h = [hashlib.sha1(b"".join(d.decode_block(*r).tobytes() for r in req)).hexdigest() for d in (do, dn)]
    assert h[0] == h[1]
    T = {"old": [], "new": []}
    pc = time.perf_counter
    for i, r in enumerate(req):
        for k, d in ((("old", do), ("new", dn)) if i % 2 == 0 else (("new", dn), ("old", do))):
            t = pc(); d.decode_block(*r); T[k].append(pc() - t)
    o, n = (np.percentile(np.array(T[k]) * 1e6, [50, 90, 99]) for k in ("old", "new"))
    print(os.path.basename(path), len(req), "predicted-view blocks, p50/p90/p99 µs: old %.1f/%.1f/%.1f new %.1f/%.1f/%.1f (p50 %.3f)" % (*o, *n, n[0] / o[0]), flush=True)
