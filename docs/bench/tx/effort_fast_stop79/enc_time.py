import sys, time, json, hashlib
from formats.scenes import read_scene
from rlfc import RlfcCodec
from formats.codec_api import EncodeOptions
g = sys.argv[1]; extra = json.loads(sys.argv[2]) if len(sys.argv) > 2 else {}
tgt = float(sys.argv[3]) if len(sys.argv) > 3 else 40.0
lf = read_scene('../shared/data/' + g)
opts = EncodeOptions(target_psnr=tgt, params=extra, keep_decoded=False)
t = time.process_time(); w = time.perf_counter()
enc = RlfcCodec().encode(lf, opts)
cpu = time.process_time() - t; wall = time.perf_counter() - w
nb = sum(len(b) for _, b in enc.sections)
print(json.dumps({"grid": g, "params": extra, "cpu": round(cpu, 2), "wall": round(wall, 2), "bytes": nb,
                  "psnr": round(enc.summary["psnr_rgb"], 4), "passes": len(enc.trace),
                  "sha": hashlib.sha1(b"".join(b for _, b in enc.sections)).hexdigest()[:10]}))
