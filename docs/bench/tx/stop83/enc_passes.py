import sys, time
import formats.parallel as fp
fp.LOCAL_THREADS = 1
from formats import EncodeOptions, read_scene
from rlfc import RlfcCodec
import rlfc.txpass as tp
orig = tp.PassCoder.run
n = [0, 0]
def run(self, step, model, progress=None, views=None, **kw):
    n[0 if views is not None else 1] += 1
    return orig(self, step, model, progress, views=views, **kw)
tp.PassCoder.run = run
lf = read_scene(sys.argv[1])
t = time.process_time()
enc = RlfcCodec().encode(lf, EncodeOptions(target_psnr=float(sys.argv[2])))
print("%-26s %s %-4s passes sample %d full %d  psnr %.3f bytes %d cpu %.1f" % (sys.argv[1].split('/')[-1], sys.argv[2], sys.argv[3], n[0], n[1], enc.summary["psnr_rgb"], sum(len(bytes(s[1])) for s in enc.sections), time.process_time() - t))
