import numpy as np, time, sys, os, resource
os.environ["OMP_NUM_THREADS"]="1"
from formats.lfcfile import open_lfc
from rlfc import RlfcDecoder
d = RlfcDecoder(open_lfc(sys.argv[1])); d.core.decode_keys()
keys=set(np.flatnonzero(d.core.is_key).tolist())
vs=[v for v in range(d.rows*d.cols) if v not in keys]
rng=np.random.default_rng(0); seq=rng.choice(vs, 60)
for v in seq[:10]: d.decode_views([v])
f0=resource.getrusage(resource.RUSAGE_SELF).ru_minflt
ts=[]
for v in seq:
    t=time.perf_counter(); d.decode_views([v]); ts.append(time.perf_counter()-t)
f1=resource.getrusage(resource.RUSAGE_SELF).ru_minflt
b3=[]
for v in vs[:6]:
    b=1e9
    for _ in range(3):
        t=time.perf_counter(); d.decode_views([v]); b=min(b,time.perf_counter()-t)
    b3.append(b)
t=time.perf_counter(); d.decode_all(threads=1); ta=time.perf_counter()-t
print(f"{os.path.basename(sys.argv[1]):22s} seq median {np.median(ts)*1e3:6.2f} ms faults/view {(f1-f0)/len(ts):5.0f}  best3 median {np.median(b3)*1e3:6.2f} ms  all {ta:.3f} s")
