# A/B (scripts: direct_images_ab.sh): a fresh open, its first whole view, a revisit, a first block, decode_all from a fresh open, beside JPEG 2000 (bench_decode's peer)
import sys, time, json, pickle, hashlib, os
import numpy as np
path = sys.argv[1]
from formats.lfcfile import open_lfc
from rlfc import RlfcDecoder
import imagecodecs
key = os.path.basename(path)[:-4] + "_" + hashlib.sha1(open(path, "rb").read()).hexdigest()[:16]
peer = pickle.load(open(f"/tmp/lfcodec_bench_decode/{key}.peer.pkl", "rb"))
blobs = peer["blobs"] if isinstance(peer, dict) else peer
d = RlfcDecoder(open_lfc(path)); d.decode_view(0, 0); d.decode_block(0, 0, 0, 0)   # imports, first uses
n = d.rows * d.cols
rng = np.random.default_rng(int(sys.argv[2]))
vs = rng.integers(0, n, 6).tolist()
r = {"open_ms": [], "first_view_ms": [], "revisit_ms": [], "j2k_view_ms": [], "first_block_ms": []}
for v in vs:
    t = time.perf_counter(); d = RlfcDecoder(open_lfc(path)); r["open_ms"].append(1e3 * (time.perf_counter() - t))
    t = time.perf_counter(); d.decode_view(*divmod(v, d.cols)); r["first_view_ms"].append(1e3 * (time.perf_counter() - t))
    t = time.perf_counter(); d.decode_view(*divmod(v, d.cols)); r["revisit_ms"].append(1e3 * (time.perf_counter() - t))
    t = time.perf_counter(); imagecodecs.jpeg2k_decode(blobs[v]); r["j2k_view_ms"].append(1e3 * (time.perf_counter() - t))
    t = time.perf_counter(); d = RlfcDecoder(open_lfc(path)); d.decode_block(*divmod(v, d.cols), 1, 1); r["first_block_ms"].append(1e3 * (time.perf_counter() - t))
out = {k: float(np.median(x)) for k, x in r.items()}
for th in (1, 2):
    t = time.perf_counter(); d = RlfcDecoder(open_lfc(path)); d.decode_all(threads=th); out[f"all_fresh_s_t{th}"] = time.perf_counter() - t
    from concurrent.futures import ThreadPoolExecutor
    t = time.perf_counter()
    with ThreadPoolExecutor(th) as pool: list(pool.map(imagecodecs.jpeg2k_decode, blobs))
    out[f"j2k_all_s_t{th}"] = time.perf_counter() - t
import resource
out["maxrss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
print(json.dumps(out))
