# usage: PYTHONPATH=CHECKOUT python unvarints_real.py CHECKOUT FILE.lfc   (each unvarints call of an open, timed alone)
import sys, time
sys.path.insert(0, sys.argv[1])
import rlfc.txsections as T
calls = []
real = T.unvarints
def spy(data, count, what):
    calls.append((bytes(data), count, what)); return real(data, count, what)
T.unvarints = spy
from formats.lfcfile import open_lfc
from rlfc import RlfcDecoder
RlfcDecoder(open_lfc(sys.argv[2]))
T.unvarints = real
tot = 0
for data, count, what in calls:
    ts = []
    for _ in range(5):
        a = time.perf_counter(); real(data, count, what); ts.append(time.perf_counter() - a)
    tot += min(ts)
    print(what, count, len(data), "%.2f ms" % (1e3 * min(ts)))
print("total %.2f ms" % (1e3 * tot))
