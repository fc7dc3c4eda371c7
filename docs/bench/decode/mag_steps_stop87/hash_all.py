import sys, hashlib
from formats.lfcfile import open_lfc
from rlfc import RlfcDecoder
import numpy as np
for f in sys.argv[1:]:
    d = RlfcDecoder(open_lfc(f'/tmp/dec/{f}.lfc'))
    h = hashlib.sha1(d.decode_all(threads=1).tobytes())
    rng = np.random.default_rng(3)
    n = 3000
    b = d.decode_blocks(rng.integers(0, d.rows * d.cols, n), rng.integers(0, d.nby, n), rng.integers(0, d.nbx, n))
    h.update(b.tobytes())
    print(f, h.hexdigest())
