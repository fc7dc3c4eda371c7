"""Captures the _magnitudes calls of three 64-request batched calls and a view (run on the code before: PYTHONPATH=OLD) into caps2.pkl for ab.py (CAPS=...)."""
import sys, pickle, numpy as np
sys.path.insert(0, __file__.rsplit('/', 1)[0])
import captures
caps = []
captures.magnitudes(caps)
from formats.lfcfile import open_lfc
from rlfc import RlfcDecoder
rng = np.random.default_rng(0)
for name in sys.argv[1:]:
    d = RlfcDecoder(open_lfc(f"/tmp/dec/{name}.lfc")); d.core.decode_keys(); d.core.decode_maps()
    n0 = len(caps)
    for _ in range(3):
        d.decode_blocks(rng.integers(0, d.rows * d.cols, 64), rng.integers(0, d.nby, 64), rng.integers(0, d.nbx, 64))
    d.decode_view(1, 2)
    print(name, len(caps) - n0)
caps = [c for c in caps if c["S"] >= 32][:8]
for c in caps:
    c["tables"] = (c["tables"].freq, c["tables"].cum)
pickle.dump(caps, open("/tmp/w87/caps2.pkl", "wb"))
print(len(caps), [c["S"] for c in caps], [c["ctx1"].size for c in caps])
