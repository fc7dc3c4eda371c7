import sys
from pathlib import Path
from tools.unseen import layers_rgba
from tools.make_golden import variants, lf_of
import rlfc.txrate as R
from rlfc import encode
from formats.codec_api import EncodeOptions
cases = {"layers_rgba": layers_rgba(Path("../shared/data"))}
v = variants()
cases["crop_rgba8"] = lf_of(v["rgba8"]); cases["crop_ga16"] = lf_of(v["ga16"])
orig = R.side_lambda
facs = [float(x) for x in sys.argv[2].split(",")]
for name in sys.argv[1].split(","):
    lf = cases[name]
    for t in (36.0, 40.0, 45.0):
        row = []
        for f in facs:
            R.side_lambda = lambda lf_, o, p, f=f: orig(lf_, o, p) * f
            e = encode(lf, EncodeOptions(profile="tx", target_psnr=t))
            row.append((f, sum(len(x) for _, x in e.sections), e.summary["psnr_rgb"] and round(e.summary["psnr_rgb"], 3)))
        print(name, t, row, flush=True)
R.side_lambda = orig
