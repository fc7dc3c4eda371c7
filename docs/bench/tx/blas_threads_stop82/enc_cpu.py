"""One encode at 40 dB, wall and CPU seconds and the sections' SHA-1 (stop 82's BLAS A/B).

    PYTHONPATH=CHECKOUT python enc_cpu.py GRID_DIR THREADS [LABEL...]

THREADS 1 sets ``formats.parallel.LOCAL_THREADS = 1``; a label ``cv1`` also sets OpenCV's pool to
one thread. Run the code before and after one after the other (fresh processes).
"""
import hashlib
import sys
import time

import formats.parallel as fp

if sys.argv[2] == "1":
    fp.LOCAL_THREADS = 1
if "cv1" in sys.argv[3:]:
    import cv2
    cv2.setNumThreads(1)
from formats import EncodeOptions, read_scene  # noqa: E402
from rlfc import RlfcCodec  # noqa: E402

lf = read_scene(sys.argv[1])
w, t = time.perf_counter(), time.process_time()
enc = RlfcCodec().encode(lf, EncodeOptions(target_psnr=40))
h = hashlib.sha1(b"".join(bytes(s[1]) for s in enc.sections)).hexdigest()[:10]
print(sys.argv[2:], "wall %.2f CPU %.2f" % (time.perf_counter() - w, time.process_time() - t), h)
