import sys, hashlib
from formats.lfcfile import open_lfc
from rlfc import RlfcDecoder
for g in sys.argv[1:]:
    d = RlfcDecoder(open_lfc(f"/tmp/dec/{g}.lfc")); r = d.renderer(cache_mib=256)
    h = hashlib.sha1()
    for s, t in (((d.rows-1)/2, (d.cols-1)/2 + min(d.rows, d.cols)/3), (0.3, 0.7), (d.rows-1.4, 1.25)):
        h.update(r.render(s, t).tobytes())
    print(g, h.hexdigest()[:16])
