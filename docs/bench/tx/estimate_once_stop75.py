import sys, os, pickle, time, resource
sys.path.insert(0, sys.argv[1])
os.environ["OMP_NUM_THREADS"] = "1"
import formats.parallel as fp; fp.LOCAL_THREADS = int(os.environ.get("LT", 1))
import rlfc.txestimate as tes
luma, struct, k = pickle.load(open(sys.argv[2], "rb"))
f0 = resource.getrusage(resource.RUSAGE_SELF)
t = time.process_time(); w = time.perf_counter()
tes.estimate_maps(luma, struct, **k)
f1 = resource.getrusage(resource.RUSAGE_SELF)
print("old" if "oldE" in sys.argv[1] else "new", os.path.basename(sys.argv[2]), "cpu %.3f wall %.3f user %.3f sys %.3f faults %d" % (
    time.process_time() - t, time.perf_counter() - w, f1.ru_utime - f0.ru_utime, f1.ru_stime - f0.ru_stime, f1.ru_minflt - f0.ru_minflt), flush=True)
