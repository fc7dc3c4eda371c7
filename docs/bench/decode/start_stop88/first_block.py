import time
t0 = time.perf_counter()
import sys
from formats import open_lfc, open_decoder
d = open_decoder(open_lfc(sys.argv[1]))
t1 = time.perf_counter()
d.decode_block(d.rows // 2, d.cols // 2, 1, 1)
t2 = time.perf_counter()
print(f"{(t1-t0)*1e3:.1f} {(t2-t0)*1e3:.1f}")
