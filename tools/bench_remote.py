"""Remote reading over a real local HTTP server: time to open, to the first block, to a view,
and the bytes and requests each costs, with an added per-request latency standing for a
network.

Usage:
    python -m tools.bench_remote FILE.lfc [--latency-ms 20] [--blocks 200] [--frames 30] [--out DIR]

Grid files also render ``--frames`` frames along an orbit from a fresh reader: open + first
frame time, bytes and requests per frame (first and mean), frame time.

LFN files stream by levels instead (:func:`run_lfn`): a fresh reader opens the base network,
then each of ``--frames`` frames grows the network by ``--grow`` neurons and renders a view
at ``--scale``; the same session runs with background prefetch off and on
(``LfnRenderer(prefetch=...)``), reporting open and first-frame time, the time frames spent
waiting in ``grow`` for the network (stalls), and the requests reads had to wait for.

Serves FILE's folder with :class:`formats.serve.FileServer` on 127.0.0.1 (byte ranges, ETags,
the latency added to every answer) and reads it with ``open_lfc(url)``.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from formats.lfcfile import open_lfc
from formats.registry import open_decoder
from formats.remote import RemoteSource
from formats.serve import FileServer
from tools.common import log, machine


def run(path: Path, latency_ms: float, n_blocks: int, cache_mib: float, page: int | None = None,
        frames: int = 30) -> dict:
    size = path.stat().st_size
    out = {"file": path.name, "bytes": size, "latency_ms": latency_ms, "cache_mib": cache_mib, "page": page,
           "machine": machine()}
    with FileServer(path.parent, latency_s=latency_ms / 1000) as srv:
        url = srv.url_of(path.name)
        t0 = time.perf_counter()
        src = RemoteSource(url, cache_bytes=int(cache_mib * (1 << 20)), page=page)
        d = open_decoder(open_lfc(src, name=url))
        out["open_s"] = time.perf_counter() - t0
        out["open_requests"], out["open_bytes"] = src.wire_requests, src.wire_bytes
        rng = np.random.default_rng(0)
        n = d.rows * d.cols
        if hasattr(d, "nby"):
            req, byt, ts = [], [], []
            for i in range(n_blocks):
                v, by, bx = int(rng.integers(n)), int(rng.integers(d.nby)), int(rng.integers(d.nbx))
                r0, b0 = src.wire_requests, src.wire_bytes
                t = time.perf_counter()
                d.decode_block(v // d.cols, v % d.cols, by, bx)
                ts.append(time.perf_counter() - t)
                req.append(src.wire_requests - r0)
                byt.append(src.wire_bytes - b0)
            out["first_block_s"] = ts[0]
            out["block_ms_p50"] = 1e3 * float(np.median(ts))
            out["block_requests_mean"] = float(np.mean(req))
            out["block_bytes_mean"] = float(np.mean(byt))
        if frames and hasattr(d, "renderer") and (d.file.meta.get("scene") or {}).get("layout") != "posed":
            from formats.campath import orbit

            t0 = time.perf_counter()                          # a fresh reader: open + first frame
            src2 = RemoteSource(url, cache_bytes=int(cache_mib * (1 << 20)), page=page)
            ren = open_decoder(open_lfc(src2, name=url)).renderer(cache_mib=cache_mib)
            req, byt, ts = [], [], []
            for i, (s_, t_, _, _) in enumerate(orbit(d.rows, d.cols, frames).tolist()):
                r0, b0, t = src2.wire_requests, src2.wire_bytes, time.perf_counter()
                ren.render(s_, t_)
                ts.append(time.perf_counter() - t)
                if i == 0:
                    out["open_and_first_frame_s"] = time.perf_counter() - t0
                req.append(src2.wire_requests - r0)
                byt.append(src2.wire_bytes - b0)
            out["frames"] = frames
            out["frame_ms_p50"] = 1e3 * float(np.median(ts))
            out["frame_requests_mean"], out["frame_bytes_mean"] = float(np.mean(req)), float(np.mean(byt))
            out["frame_requests_first"], out["frame_bytes_first"] = req[0], byt[0]
            out["render_wire_bytes"] = src2.wire_bytes
        t = time.perf_counter()
        d.decode_view(d.rows // 2, d.cols // 2)
        out["view_s"] = time.perf_counter() - t
        t = time.perf_counter()
        d.decode_all()
        out["all_s"] = time.perf_counter() - t
        out["total_wire_bytes"], out["total_requests"] = src.wire_bytes, src.wire_requests
        out["peak_cached_bytes"] = src.cached_bytes
    return out


def lfn_session(url: str, page: int | None, cache_mib: float, frames: int, grow: float,
                scale: float, prefetch: int) -> dict:
    """One streaming session of an LFN file (see the module doc)."""
    from lfn_stream import LfnRenderer

    t0 = time.perf_counter()
    src = RemoteSource(url, cache_bytes=int(cache_mib * (1 << 20)), page=page)
    r = LfnRenderer(open_lfc(src, name=url), device="cpu", max_neurons=0, prefetch=prefetch)  # the base network
    pose = r.pose(0, 0)                                 # the cameras (meta.more, at the end of the file)
    out = {"prefetch": prefetch, "open_s": time.perf_counter() - t0, "open_requests": src.read_requests}
    stalls, frame_ms, waited = [], [], []
    full = float(r.cfg.max_neurons)
    for i in range(frames):
        t = time.perf_counter()
        n0 = src.read_requests
        neurons = r.grow(min(r.cfg.min_neurons + grow * i, full))
        t1 = time.perf_counter()
        r.render_pose(pose, neurons, scale)
        frame_ms.append(1e3 * (time.perf_counter() - t))
        stalls.append(1e3 * (t1 - t))
        waited.append(src.read_requests - n0)
        if i == 0:
            out["open_and_first_frame_s"] = time.perf_counter() - t0
        if neurons >= full and i > 0:
            break
    src.wait_prefetch()
    out.update({"frames": len(frame_ms), "neurons": float(r.neurons), "frame_ms_mean": float(np.mean(frame_ms)),
                "stall_ms_mean": float(np.mean(stalls)), "stall_ms_max": float(np.max(stalls)),
                "frames_that_waited": int(np.count_nonzero(waited)), "read_requests": src.read_requests,
                "wire_requests": src.wire_requests, "wire_bytes": src.wire_bytes,
                "prefetched_bytes": src.prefetched_bytes})
    src.close()
    return out


def run_lfn(path: Path, latency_ms: float, page: int | None, cache_mib: float, frames: int, grow: float,
            scale: float, prefetch: int, rounds: int = 2) -> dict:
    """Streaming sessions of an LFN file over a local server, prefetch off and on, interleaved."""
    out = {"file": path.name, "bytes": path.stat().st_size, "latency_ms": latency_ms, "page": page,
           "grow_per_frame": grow, "scale": scale, "machine": machine(), "sessions": []}
    with FileServer(path.parent, latency_s=latency_ms / 1000) as srv:
        url = srv.url_of(path.name)
        for _ in range(rounds):
            for ahead in (0, prefetch):
                res = lfn_session(url, page, cache_mib, frames, grow, scale, ahead)
                log(json.dumps(res))
                out["sessions"].append(res)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m tools.bench_remote", description=__doc__.split("\n\n")[0])
    ap.add_argument("file")
    ap.add_argument("--latency-ms", type=float, default=20.0)
    ap.add_argument("--blocks", type=int, default=200)
    ap.add_argument("--cache-mib", type=float, default=64.0)
    ap.add_argument("--page", type=int, default=None, help="page size in bytes (default 64 KiB)")
    ap.add_argument("--frames", type=int, default=30, help="rendered frames along an orbit (grid files; 0 = none)")
    ap.add_argument("--grow", type=float, default=4.0, help="LFN: neurons added per frame")
    ap.add_argument("--scale", type=float, default=0.5, help="LFN: render scale of the frames")
    ap.add_argument("--prefetch", type=int, default=16, help="LFN: neurons fetched ahead in the prefetch session")
    ap.add_argument("--out", default=None)
    a = ap.parse_args(argv)
    if open_lfc(a.file).meta.get("codec") == "lfn":
        res = run_lfn(Path(a.file), a.latency_ms, a.page, a.cache_mib, a.frames, a.grow, a.scale, a.prefetch)
    else:
        res = run(Path(a.file), a.latency_ms, a.blocks, a.cache_mib, a.page, a.frames)
    log(json.dumps(res, indent=1))
    if a.out:
        Path(a.out).mkdir(parents=True, exist_ok=True)
        (Path(a.out) / "remote.json").write_text(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
