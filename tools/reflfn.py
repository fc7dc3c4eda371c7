"""Reference decoder of LFN files (docs/FORMAT.md, "LFN codec"), in float64 numpy.

Part of the fuzzer's oracle (:mod:`tools.refdecode`); written from the text of FORMAT.md, not
from ``lfn_stream``. The library renders in float32 (torch), so the two agree within one grey
level, not bit for bit.
"""
from __future__ import annotations

import numpy as np

from tools.refdecode import RefError, need, pint

DT = {"fp16": "<f2", "fp32": "<f4"}


def fnum(v) -> float:
    need(type(v) in (int, float), f"number {v!r}")
    try:
        x = float(v)
    except OverflowError:
        raise RefError(f"number {v!r} beyond float64") from None
    need(np.isfinite(x), f"finite number {v!r}")
    return x


def merge_more(meta: dict, secs: dict[str, bytes]) -> dict:
    """FORMAT.md "Moved metadata": put the keys of section meta.more back into scene/config."""
    import json
    import zlib

    if "more" not in meta:
        return meta
    names = meta["more"]
    need(type(names) is list and 1 <= len(names) <= 64 and all(type(k) is str for k in names)
         and len(set(names)) == len(names), "more: list of names")
    want = {}
    for k in names:
        part, _, key = k.partition(".")
        need(part in ("scene", "config") and key and type(meta.get(part)) is dict and key not in meta[part],
             f"more: name {k!r}")
        want.setdefault(part, set()).add(key)
    need("meta.more" in secs, "meta.more present")
    d = zlib.decompressobj()
    try:
        raw = d.decompress(secs["meta.more"], (64 << 20) + 1)
    except zlib.error as e:
        raise RefError(f"meta.more: {e}") from None
    need(len(raw) <= 64 << 20 and d.eof and not d.unused_data and not d.unconsumed_tail, "meta.more stream")
    try:
        more = json.loads(raw.decode("utf-8"), parse_constant=lambda c: (_ for _ in ()).throw(RefError(c)))
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise RefError(f"meta.more: {e}") from None
    need(type(more) is dict and set(more) == set(want)
         and all(type(more[p]) is dict and set(more[p]) == want[p] for p in more), "meta.more keys")
    out = dict(meta)
    for p in more:
        out[p] = {**meta[p], **more[p]}
    return out


class RefLfn:
    def __init__(self, meta: dict, secs: dict[str, bytes]):
        need(meta.get("codec_version") in (1, 2, 3), "codec version")
        meta, secs = merge_more(meta, secs), dict(secs)
        c, s = meta["config"], meta["scene"]
        net = c["network"]
        v1 = meta["codec_version"] == 1          # version 1 named the sizes *_width; decoders read both

        def pick(a, b):
            if not v1:
                return net[a]
            need((a in net) != (b in net), f"network size named once ({a} or {b})")
            return net[a] if a in net else net[b]
        self.D = pint(net["depth"], 1, 32)
        self.m = pint(pick("min_neurons", "min_width"), 1, 4096)
        self.M = pint(pick("max_neurons", "max_width"), self.m, 4096)
        self.k_occ = pint(pick("occupancy_neurons", "occupancy_width"), 0, 4096)
        need(net.get("in_features", 6) == 6 and net.get("out_features", 4) == 4, "features")
        wd = c.get("weights", "fp16")              # FORMAT.md: fp16 when absent
        need(wd in DT, "weights dtype")
        dt = np.dtype(DT[wd])
        self.centre = [fnum(x) for x in c["norm"]["centre"]]
        self.radius = fnum(c["norm"]["radius"])
        need(len(self.centre) == 3 and self.radius > 0, "norm")
        self.rows, self.cols = pint(s["rows"], 1, 65536), pint(s["cols"], 1, 65536)
        self.H, self.W = pint(s["height"], 1, 2 ** 26), pint(s["width"], 1, 2 ** 26)
        need(self.H * self.W <= 2 ** 26, "pixels per view")
        self.C = pint(s["channels"], 1, 4)
        need(s["dtype"] in ("uint8", "uint16"), "dtype")
        self.dtype = np.dtype(s["dtype"])
        self.focal = [fnum(x) for x in s.get("focal", [1, 1])]
        self.principal = [fnum(x) for x in s.get("principal", [self.W / 2, self.H / 2])]
        n = self.rows * self.cols
        if "c2w" in s:
            poses = np.array(s["c2w"], dtype=float)
            need(poses.shape == (self.rows, self.cols, 4, 4), "c2w shape")
            self.poses = poses.reshape(n, 4, 4)
        else:
            if "positions" in s:
                pos = np.array(s["positions"], dtype=float)
                need(pos.shape == (self.rows, self.cols, 3), "positions shape")
            else:
                bx, by = (fnum(x) for x in s.get("baseline", [1, 1]))
                pos = np.array([[[cc * bx, -r * by, 0.0] for cc in range(self.cols)] for r in range(self.rows)])
            self.poses = np.tile(np.eye(4), (n, 1, 1))
            self.poses[:, :3, 3] = pos.reshape(n, 3)
        need(np.isfinite(self.poses).all(), "finite poses")
        for pose in self.poses:          # FORMAT.md: usable cameras
            need(np.abs(pose[:3, :3]).max() <= 2 ** 20 and abs(np.linalg.det(pose[:3, :3])) >= 1e-9, "camera rotation")
            need(np.abs((pose[:3, 3] - np.array(self.centre)) / self.radius).max() <= 2 ** 20, "camera origin")

        def vals(name, count):
            need(name in secs and len(secs[name]) == count * dt.itemsize, f"{name} length")
            v = np.frombuffer(secs[name], dt).astype(np.float64)
            need((np.abs(v) <= 65504).all(), f"{name}: weights within ±65504")
            return list(v)

        m, D = self.m, self.D
        base = vals("lfn.base", 6 * m + 3 * m + (D - 1) * (m * m + 3 * m) + 4 * m + 4)
        steps = []
        if meta["codec_version"] >= 3:       # one section lfn.steps, the steps one after another
            sizes = [(6 + 3 + (D - 1) * (2 * j + 4) + 4) * dt.itemsize for j in range(m, self.M)]
            if "lfn.steps" in secs:
                need(len(secs["lfn.steps"]) == sum(sizes), "lfn.steps length")
                a = 0
                for k, size in enumerate(sizes):
                    secs[f"lfn.step.{k:04d}"] = secs["lfn.steps"][a:a + size]
                    a += size
        while m + len(steps) < self.M and f"lfn.step.{len(steps):04d}" in secs:
            j = m + len(steps)
            steps.append(vals(f"lfn.step.{len(steps):04d}", 6 + 3 + (D - 1) * (2 * j + 4) + 4))
        w = self.w = m + len(steps)
        self.Wl = [np.zeros((w, 6 if i == 0 else w)) for i in range(D)]
        self.b, self.g, self.be = (np.zeros((D, w)) for _ in range(3))
        self.ow, self.ob = np.zeros((4, w)), np.zeros(4)
        it = iter(base)
        for i in range(D):
            k = 6 if i == 0 else m
            for r in range(m):
                for cc in range(k):
                    self.Wl[i][r, cc] = next(it)
            for arr in (self.b, self.g, self.be):
                for r in range(m):
                    arr[i, r] = next(it)
        for o in range(4):
            for cc in range(m):
                self.ow[o, cc] = next(it)
        for o in range(4):
            self.ob[o] = next(it)
        for s_i, sv in enumerate(steps):
            j, it = m + s_i, iter(sv)
            for cc in range(6):
                self.Wl[0][j, cc] = next(it)
            self.b[0, j], self.g[0, j], self.be[0, j] = next(it), next(it), next(it)
            for i in range(1, D):
                for cc in range(j + 1):
                    self.Wl[i][j, cc] = next(it)
                for r in range(j):
                    self.Wl[i][r, j] = next(it)
                self.b[i, j], self.g[i, j], self.be[i, j] = next(it), next(it), next(it)
            for o in range(4):
                self.ow[o, j] = next(it)
        self.occ = None
        if self.C in (2, 4) and self.k_occ and "lfn.occ" in secs:
            k = self.k_occ
            v = np.array(vals("lfn.occ", 6 * k + k + k * k + k + k + 1))
            a = 0

            def take(nv, shape):
                nonlocal a
                a += nv
                return v[a - nv:a].reshape(shape)
            self.occ = [take(6 * k, (k, 6)), take(k, (k,)), take(k * k, (k, k)), take(k, (k,)), take(k, (1, k)),
                        take(1, (1,))]
        self.levels = w - m

    def rays(self, pose: np.ndarray) -> np.ndarray:
        """(H·W, 6) Plücker rays through the pixel centres, float32 as stored by the renderer."""
        ys, xs = np.meshgrid(np.arange(self.H) + 0.5, np.arange(self.W) + 0.5, indexing="ij")
        u = (xs - self.principal[0]) / self.focal[0]
        v = -(ys - self.principal[1]) / self.focal[1]
        d = np.stack([u, v, -np.ones_like(u)], -1).reshape(-1, 3) @ pose[:3, :3].T
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        o = (pose[:3, 3] - np.array(self.centre)) / self.radius
        with np.errstate(over="ignore", invalid="ignore"):
            x = np.concatenate([d, np.cross(np.broadcast_to(o, d.shape), d)], 1).astype(np.float32)
        need(np.isfinite(x).all(), "rays finite in float32")
        return x.astype(np.float64)

    def forward(self, x: np.ndarray, n: int) -> np.ndarray:
        h = x
        for i in range(self.D):
            z = h @ self.Wl[i][:n, :h.shape[1]].T + self.b[i, :n]
            mu = z.mean(1, keepdims=True)
            var = ((z - mu) ** 2).mean(1, keepdims=True)
            h = np.maximum((z - mu) / np.sqrt(var + 1e-5) * self.g[i, :n] + self.be[i, :n], 0)
        return 1 / (1 + np.exp(-(h @ self.ow[:, :n].T + self.ob)))

    def decode(self, level: int) -> np.ndarray:
        need(0 <= level <= self.levels, "level")
        n = self.w - level
        peak = float(np.iinfo(self.dtype).max)
        out = np.zeros((self.rows * self.cols, self.H * self.W, self.C), self.dtype)
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            for v, pose in enumerate(self.poses):
                x = self.rays(pose)
                rgba = np.zeros((x.shape[0], 4))
                keep = np.ones(x.shape[0], bool)
                if self.occ is not None:
                    W1, b1, W2, b2, W3, b3 = self.occ
                    h = np.maximum(np.maximum(x @ W1.T + b1, 0) @ W2.T + b2, 0)
                    keep = 1 / (1 + np.exp(-(h @ W3.T + b3)[:, 0])) > 0.1
                if keep.any():
                    rgba[keep] = self.forward(x[keep], n)
                a = np.clip(rgba, 0, 1)
                al = a[:, 3:4]
                un = np.where(al >= 2.0 ** -20, a / np.maximum(al, 2.0 ** -20), 0)
                px = {1: a[:, :1], 2: np.concatenate([un[:, :1], al], 1), 3: a[:, :3],
                      4: np.concatenate([un[:, :3], al], 1)}[self.C]
                out[v] = np.rint(np.clip(px, 0, 1) * peak)
        return out.reshape(self.rows, self.cols, self.H, self.W, self.C)
