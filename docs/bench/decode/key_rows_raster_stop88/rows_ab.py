"""Decoding n block rows of one predicted key (its references decoded), raster bands against
block by block, alternated in one process: median ms per call, n = 1, 2, 3, 4, 8 and all rows."""
import sys, time, statistics, numpy as np
from formats.lfcfile import open_lfc
from rlfc import RlfcDecoder
import rlfc.profiles.tx_lazy as tl
for g in sys.argv[2:]:
    d = RlfcDecoder(open_lfc(f"/tmp/dec/{g}.lfc"))
    d.decode_keys()
    c = d.core
    keys = [int(k) for k in c.lay.keys]
    s = max(i for i, k in enumerate(keys) if not c.lay.intra[k] and k not in c.img_of)
    out = []
    for n in (1, 2, 3, 4, 8, c.nby):
        res = {False: [], True: []}
        for r in range(int(sys.argv[1])):
            for flag in ((False, True) if r % 2 else (True, False)):
                tl.KEY_ROWS_RASTER_MIN = 1 if flag else 10 ** 9
                c._key_done[s] = False
                c._keys_all = False
                need = np.zeros(c._key_done.shape, bool)
                a = (r * 5) % max(1, c.nby - n + 1)
                need[s, a:a + n] = True
                t = time.perf_counter(); c._have_keys(need); res[flag].append(time.perf_counter() - t)
        b, ra = statistics.median(res[False]), statistics.median(res[True])
        out.append(f"n={n}: {b*1e3:.2f} → {ra*1e3:.2f} ms ({ra/b:.2f}×)")
    print(g, "; ".join(out), flush=True)
