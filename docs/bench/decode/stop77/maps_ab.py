"""old vs new rlfc.txmaps parsing (the shared map at open, each map's stream) on real files:
the same values checked, calls alternated."""
import sys, os, time, types, subprocess
sys.path.insert(0, "/work/main")
import numpy as np
from formats.lfcfile import open_lfc
from rlfc import RlfcDecoder
import rlfc.txmaps as new
src = subprocess.run(["git", "-C", "/work/main", "show", "HEAD:rlfc/txmaps.py"], capture_output=True, text=True).stdout
old = types.ModuleType("rlfc._old_txmaps"); old.__package__ = "rlfc"; sys.modules[old.__name__] = old
exec(compile(src, "old_txmaps", "exec"), old.__dict__)
for g in sys.argv[1:]:
    d = RlfcDecoder(open_lfc(g)); ms = d.core._map_store
    raw, (ny, nx), n_maps = ms.raw, ms.shape, ms.done.size
    b = np.frombuffer(raw, np.uint8)
    ends = np.flatnonzero(b[1:] < 128); head = 1 + int(ends[n_maps + 1]) + 1
    lens = new.unvarints(raw[1:head], n_maps + 2, "x"); pos = head + int(lens[0])
    shared = (raw[pos:pos + int(lens[1])], ms.tabs, ny, nx, ms.version, "x")
    streams = [(raw, int(ms.starts[m]), int(ms.starts[m + 1]), ms.tabs, ny, nx, ms.n_modes, ms.version, "x") for m in range(n_maps)]
    assert old._shared_map(*shared) == new._shared_map(*shared)
    for a in streams:
        assert old._map_stream(*a) == new._map_stream(*a)
    out = [os.path.basename(g)]
    for label, fname, calls in (("shared map", "_shared_map", [shared]), ("per map", "_map_stream", streams)):
        T = {"old": [], "new": []}
        for r in range(10):
            for k, m in ((("old", old), ("new", new)) if r % 2 == 0 else (("new", new), ("old", old))):
                f = getattr(m, fname)
                t = time.perf_counter()
                for a in calls: f(*a)
                T[k].append((time.perf_counter() - t) / len(calls))
        o, n = np.median(T["old"]), np.median(T["new"])
        out.append("%s %.2f -> %.2f ms (x %.3f)" % (label, o * 1e3, n * 1e3, n / o))
    print(", ".join(out) + "; the same values", flush=True)
