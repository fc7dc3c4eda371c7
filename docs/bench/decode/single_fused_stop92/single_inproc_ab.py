"""In one process: decode_block's one-request path of an old checkout (OLD, first argument) and of this
one alternated in slices of 300 requests (their per-view caches swapped), p50/p90/p99 µs each
(every key view and map decoded first; 16 slices of 300 random requests per file).

Usage: OMP_NUM_THREADS=1 python docs/bench/decode/single_fused_stop92/single_inproc_ab.py OLD_CHECKOUT FILE.lfc ...
"""
import sys, time, types, importlib.util
import numpy as np
from formats.lfcfile import open_lfc
from rlfc import RlfcDecoder
import rlfc.profiles.tx_single as new_ts

OLD = sys.argv[1]

def load(name, path, pkg):
    spec = importlib.util.spec_from_file_location(name, path)
    m = importlib.util.module_from_spec(spec); m.__package__ = pkg
    sys.modules[name] = m; spec.loader.exec_module(m); return m
old_tsb = load("rlfc.txsample_block_old", OLD + "/rlfc/txsample_block.py", "rlfc")
old_ts = load("rlfc.profiles.tx_single_old", OLD + "/rlfc/profiles/tx_single.py", "rlfc.profiles")
old_ts.predict_block_pixels = old_tsb.predict_block_pixels
old_ts.block_pixel_refs = old_tsb.block_pixel_refs
old_dec = load("rlfc.decoder_old", OLD + "/rlfc/decoder.py", "rlfc")
import rlfc.decoder as new_dec
out = {}
for path in sys.argv[2:]:
    d = RlfcDecoder(open_lfc(path)); d.decode_keys(); d.decode_maps()
    core = d.core
    vers = {"old": (types.MethodType(old_ts.SingleRequests.block_pixels, core), types.MethodType(old_ts.SingleRequests._pixel_refs, core), types.MethodType(old_ts.SingleRequests._cell_map, core), {}, {}),
            "new": (types.MethodType(new_ts.SingleRequests.block_pixels, core), types.MethodType(new_ts.SingleRequests._pixel_refs, core), types.MethodType(new_ts.SingleRequests._cell_map, core), {}, {})}
    dbs = {"old": types.MethodType(old_dec.RlfcDecoder.decode_block, d), "new": types.MethodType(new_dec.RlfcDecoder.decode_block, d)}
    readies = {"old": {}, "new": {}}

    def use(k):
        bp, pr, cm, c1, c2 = vers[k]
        core.block_pixels, core._pixel_refs, core._cell_map = bp, pr, cm
        core._pixref_cache, core._cell_maps = c1, c2
        core._pix_ready = readies[k]
        d.decode_block = dbs[k]
    rng = np.random.default_rng(1); n = d.rows * d.cols
    lat = {"old": [], "new": []}
    for k in ("old", "new"):       # warm: every view's constants built once
        use(k)
        for v in range(n):
            d.decode_block(v // d.cols, v % d.cols, 0, 0)
    for rnd in range(16):
        req = [(int(v) // d.cols, int(v) % d.cols, int(y), int(x)) for v, y, x in
               zip(rng.integers(0, n, 300), rng.integers(0, d.nby, 300), rng.integers(0, d.nbx, 300))]
        for k in (("old", "new") if rnd % 2 == 0 else ("new", "old")):
            use(k)
            for q in req:
                t = time.perf_counter(); d.decode_block(*q); lat[k].append(time.perf_counter() - t)
    s = {k: np.percentile(np.array(v) * 1e6, [50, 90, 99]) for k, v in lat.items()}
    print("%-32s old p50/p90/p99 %5.1f %5.1f %6.1f | new %5.1f %5.1f %6.1f | p50 ratio %.3f" % (
        path.split("/")[-1], *s["old"], *s["new"], s["new"][0] / s["old"][0]), flush=True)
