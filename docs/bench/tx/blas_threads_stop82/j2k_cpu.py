"""JPEG 2000 (imagecodecs' OpenJPEG) coding every view at level=40 on one thread: CPU-s, best of 2.

    OMP_NUM_THREADS=1 python j2k_cpu.py GRID_DIR...
"""
import sys
import time

import imagecodecs
import numpy as np

from formats import read_scene

for g in sys.argv[1:]:
    lf = read_scene(g)
    v = np.asarray(lf.views).reshape(-1, *lf.views.shape[-3:])
    best = 1e9
    for _ in range(2):
        t = time.process_time()
        for a in v:
            imagecodecs.jpeg2k_encode(a, level=40.0, numthreads=1)
        best = min(best, time.process_time() - t)
    print(g.split("/")[-1], "J2K encode CPU-s %.2f" % best)
