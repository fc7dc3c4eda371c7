import sys, os, time, types, subprocess, hashlib
sys.path.insert(0, "/work/main")
os.environ["OMP_NUM_THREADS"] = "1"
import formats.parallel as fp; fp.LOCAL_THREADS = 1
from formats.scenes import read_scene
from formats.codec_api import EncodeOptions
import rlfc.txencode as te, rlfc.txestimate as new
src = subprocess.run(["git", "-C", "/work/main", "show", f"{sys.argv[1]}:rlfc/txestimate.py"], capture_output=True, text=True).stdout
old = types.ModuleType("rlfc._old_est"); old.__package__ = "rlfc"
exec(compile(src, "old_txestimate.py", "exec"), old.__dict__)
R = int(sys.argv[2])
for g in sys.argv[3:]:
    lf = read_scene("/work/shared/data/" + g)
    tim = {"old": [], "new": []}
    shas = set()
    for r in range(R):
        for name, mod in (("old", old), ("new", new)) if r % 2 == 0 else (("new", new), ("old", old)):
            te.estimate_maps, te.reprice_maps_both = mod.estimate_maps, mod.reprice_maps_both
            t = time.process_time()
            e = te.encode_tx(lf, EncodeOptions(target_psnr=40.0))
            tim[name].append(time.process_time() - t)
            shas.add(hashlib.sha1(b"".join(bytes(x) for _, x in e.sections)).hexdigest()[:12])
            del e
    import statistics as st
    mo, mn = st.median(tim["old"]), st.median(tim["new"])
    print(g, "files", shas, "old", [round(x, 2) for x in tim["old"]], "new", [round(x, 2) for x in tim["new"]],
          "median x", round(mn / mo, 3), flush=True)
