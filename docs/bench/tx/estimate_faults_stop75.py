import sys, os, resource, collections, pickle
sys.path.insert(0, sys.argv[1])
os.environ["OMP_NUM_THREADS"] = "1"
import formats.parallel as fp; fp.LOCAL_THREADS = 1
import rlfc.txestimate as tes
flt = lambda: resource.getrusage(resource.RUSAGE_SELF).ru_minflt
acc = collections.Counter()
def wrap(obj, name):
    f = getattr(obj, name, None)
    if f is None: return
    def w(*a, **k):
        f0 = flt(); r = f(*a, **k); acc[name] += flt() - f0; return r
    setattr(obj, name, w)
for n in ["costs_global_many", "costs_maps", "_maps_cell", "_global_cell", "_ref_luma", "_scratch", "_grid"]:
    wrap(tes.Estimator, n)
luma, struct, k = pickle.load(open(sys.argv[2], "rb"))
f0 = flt()
tes.estimate_maps(luma, struct, **k)
print("estimate faults", flt() - f0, dict(acc))
