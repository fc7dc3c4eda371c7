"""Structure-aware fuzzing of every .lfc decoder, with valid checksums.

Each mutant is a real file (the golden fixtures: every RLFC profile, lossless and lossy, RGB,
RGBA, 16-bit grey + alpha, and an LFN file) with one to three structure-aware changes — JSON
metadata fields replaced by hostile values, deleted, duplicated or nested; section bytes
changed, integers overwritten with boundary values, spans zeroed, cut, repeated or moved;
sections dropped, reordered or renamed — re-assembled with *valid* checksums, so that only
the decoder's own validation stands between the file and the pixels.

Every accepted mutant is decoded along every path — memory-mapped file, in-memory buffer,
HTTP-style byte ranges, full/view/batched-block/single-block/torch decoders, every level —
and the paths must agree bit for bit (or all raise a typed :class:`~formats.errors.LfcError`).
Every accepted mutant is then decoded again by a reference reader written from docs/FORMAT.md
alone, at every level, and must give the same pixels: :mod:`tools.refdecode` (slow Python;
profiles bise and dcp bit for bit, LFN within one grey level in float64) or, for profile tx versions 2-6, the
browser viewer's JavaScript decoder under Node (``tools/web_decode.mjs``; its int32 planes must
equal the library's). A reference that refuses a file the library accepted is a mismatch too.
Mutants run in a worker process under an address-space limit with a per-mutant deadline, so a
huge allocation, a crash or a hang is counted, not suffered.

Outcomes: ``typed`` (an LfcError), ``exact`` (accepted, all paths agree; ``referenced`` counts
those a reference decoder also reproduced; ``sampled`` counts LFN mutants whose metadata declares
more than :data:`LFN_RENDER_PIXELS` pixels — a network renders any declared size within the
limits, at about 1 µs a pixel on a CPU — so only one view per level is rendered, or none where
one view is that large, and no reference runs; ``illcond`` counts LFN mutants whose weights
amplify float32 rounding beyond a grey level: the reference differs only at pixels where the
library's own result moves as far when the same rays are evaluated one per batch instead of
together, e.g. a hidden weight of 17 328 moved in from other bytes), and the defects ``untyped`` (any other exception),
``mismatch`` (paths disagree, or disagree with the reference), ``crash`` (the worker died, e.g.
out of memory), ``hang`` (over the deadline).

Usage::

    python -m tools.fuzz --minutes 10 [--seed 1] [--mem-mib 3072] [--out report.json]
"""
from __future__ import annotations

import argparse
import json
import math
import multiprocessing as mp
import os
import resource
import tempfile
import time
import traceback
import zlib
from pathlib import Path

import shutil
import subprocess

import numpy as np

from formats.container import ByteRangeSource, Container, build_container

ROOT = Path(__file__).resolve().parent.parent
CORPUS = ROOT / "tests" / "data" / "golden"
DEFECTS = ("untyped", "mismatch", "crash", "hang")
COUNTS = ("tried", "typed", "exact", "referenced", "sampled", "illcond") + DEFECTS
LFN_RENDER_PIXELS = 1 << 21     # an LFN mutant declaring more pixels than this is rendered on a sample
HOSTILE = [0, -1, 1, 2, 3, 7, 8, 255, 256, 65535, 65536, 2 ** 31 - 1, 2 ** 31, 2 ** 32, 2 ** 40, 2 ** 63,
           -2 ** 63, 10 ** 30, 0.5, -0.0, 1e308, 16.0, "", "x", "tx", "bise", "uint8", "float64", None, True,
           False, [], {}, [0], [[]], [1, 2, 3], {"a": 1}]


def corpus_files() -> list[Path]:
    """The fuzz corpus: every golden fixture."""
    return sorted(CORPUS.glob("*.lfc"))


def split_file(blob: bytes) -> tuple[dict, list[tuple[str, bytes]]]:
    """A valid .lfc → (metadata dict, [(section name, bytes)] after "meta")."""
    c = Container(blob)
    meta = json.loads(bytes(c.read("meta")))
    secs = [(n, bytes(c.read(n))) for n in c.sections if n != "meta"]
    return meta, secs


def join_file(meta: dict, secs: list) -> bytes:
    """The inverse of :func:`split_file`: a valid container of ``meta`` and ``secs`` (checksums
    recomputed), for hand-made hostile files."""
    return b"".join(bytes(p) for p in build_container(json.dumps(meta).encode(), secs))


# -- mutations -------------------------------------------------------------------------------
def _paths(obj, path=()):
    """Every (path, value) in a JSON tree, containers included."""
    yield path, obj
    if isinstance(obj, dict):
        for k, v in obj.items():
            yield from _paths(v, path + (k,))
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            yield from _paths(v, path + (i,))


def _get(obj, path):
    for p in path:
        obj = obj[p]
    return obj


def _set(obj, path, value):
    _get(obj, path[:-1])[path[-1]] = value


def mutate_meta(meta: dict, rng: np.random.Generator) -> str:
    """One change to the metadata tree (in place) → a description."""
    paths = [p for p, _ in _paths(meta) if p and p[0] in ("config", "scene", "codec_version", "codec")]
    path = paths[int(rng.integers(len(paths)))]
    val = _get(meta, path)
    parent = _get(meta, path[:-1])
    op = int(rng.integers(7))
    if op == 0 or (op == 1 and not (isinstance(val, int) and not isinstance(val, bool))):
        new = HOSTILE[int(rng.integers(len(HOSTILE)))]
        _set(meta, path, new)
        return f"meta {path} = {new!r}"
    if op == 1:
        new = [val + 1, val - 1, val * 2, val * 1000 + 1, -val, val // 2, val + 2 ** 32][int(rng.integers(7))]
        _set(meta, path, new)
        return f"meta {path} = {new!r}"
    if op == 2:
        if isinstance(parent, dict):
            del parent[path[-1]]
        else:
            parent.pop(path[-1])
        return f"meta del {path}"
    if op == 3 and isinstance(parent, list):
        parent.insert(path[-1], json.loads(json.dumps(val)))
        return f"meta dup {path}"
    if op == 4:
        deep = val
        for _ in range(int(rng.integers(1, 40))):
            deep = [deep]
        _set(meta, path, deep)
        return f"meta nest {path}"
    if op == 5 and isinstance(val, list) and val:
        val.append(json.loads(json.dumps(val[int(rng.integers(len(val)))])))
        return f"meta append {path}"
    if isinstance(val, float):
        _set(meta, path, int(val) if math.isfinite(val) else 0)
        return f"meta int {path}"
    if isinstance(val, int) and not isinstance(val, bool):
        _set(meta, path, float(val) + 0.5)
        return f"meta float {path}"
    _set(meta, path, HOSTILE[int(rng.integers(len(HOSTILE)))])
    return f"meta {path} = hostile"


def mutate_bytes(data: bytes, rng: np.random.Generator) -> tuple[bytes, str]:
    """One change to a section's bytes → (new bytes, description)."""
    b = bytearray(data)
    n = len(b)
    op = int(rng.integers(9)) if n else 6
    at = int(rng.integers(n)) if n else 0
    if op == 0:
        b[at] = int(rng.integers(256))
        return bytes(b), f"byte {at}"
    if op == 1:
        b[at] ^= 1 << int(rng.integers(8))
        return bytes(b), f"bit {at}"
    if op == 2:
        w = [1, 2, 4, 8][int(rng.integers(4))]
        v = [0, 1, 2 ** (8 * w) - 1, 2 ** (8 * w - 1), 2 ** (8 * w - 1) - 1, int(rng.integers(2 ** 16))][int(rng.integers(6))]
        v %= 2 ** (8 * w)
        b[at:at + w] = v.to_bytes(w, "little")[:max(0, min(w, n - at))]
        return bytes(b), f"int{8 * w} {at} = {v}"
    if op == 3:
        ln = int(rng.integers(1, 65))
        b[at:at + ln] = bytes([0 if rng.integers(2) else 255]) * len(b[at:at + ln])
        return bytes(b), f"fill {at}+{ln}"
    if op == 4:
        return bytes(b[:at]), f"cut {at}"
    if op == 5:
        ln = int(rng.integers(1, 65))
        return bytes(b[:at] + b[at + ln:]), f"delete {at}+{ln}"
    if op == 6:
        ln = int(rng.integers(1, 65))
        return bytes(b[:at] + rng.integers(0, 256, ln, dtype=np.uint8).tobytes() + b[at:]), f"insert {at}+{ln}"
    if op == 7:
        ln = int(rng.integers(1, 65))
        return bytes(b[:at] + b[at:at + ln] + b[at:]), f"repeat {at}+{ln}"
    src = int(rng.integers(n))
    ln = int(rng.integers(1, 65))
    piece = b[src:src + ln]
    b[at:at + len(piece)] = piece
    return bytes(b[:n]), f"move {src}->{at}+{ln}"


def run_lengths(index: bytes) -> np.ndarray:
    """Byte lengths of the block runs from an ``rlfc.index`` section (zlib-coded lengths in
    dcp files, raw u32 offsets otherwise)."""
    try:
        return np.frombuffer(zlib.decompress(index), "<u4").astype(np.int64)
    except zlib.error:
        return np.diff(np.frombuffer(index[:len(index) // 4 * 4], "<u4").astype(np.int64))


def mutate_run(meta: dict, secs: list, rng: np.random.Generator) -> str | None:
    """A change inside one block run of an RLFC ``rlfc.blocks`` section (its bitmap, a block
    header or the first payload bytes), or None when the file has no such runs."""
    names = [n for n, _ in secs]
    if "rlfc.blocks" not in names or "rlfc.index" not in names:
        return None
    try:
        lengths = run_lengths(dict(secs)["rlfc.index"])
        lay = meta["config"]["layout"]
        nbm, hs = int(lay["bitmap_bytes"]), int(lay["off_bytes"]) + 3 * int(meta["config"]["planes"])
    except (zlib.error, KeyError, TypeError, ValueError):
        return None
    if (lengths < 0).any() or nbm < 1 or hs < 0:     # (a layout an earlier mutation changed: no run to aim at)
        return None
    runs = np.flatnonzero(lengths)
    if runs.size == 0:
        return None
    r = int(runs[rng.integers(runs.size)])
    start = int(lengths[:r].sum())
    i = names.index("rlfc.blocks")
    b = bytearray(secs[i][1])
    where = int(rng.integers(3))
    if where == 0:                                   # the bitmap
        at = start + int(rng.integers(nbm))
        val = [0xFF, 0, int(rng.integers(256))][int(rng.integers(3))]
    else:                                            # a header field or an early payload byte
        at = start + nbm + int(rng.integers(max(1, min(int(lengths[r]) - nbm, 4 * hs))))
        val = [0xFF, 0, int(rng.integers(256)), -1][int(rng.integers(4))]
    if at >= len(b):                                 # the section was already cut shorter
        return None
    b[at] = b[at] ^ 1 if val < 0 else val
    secs[i] = ("rlfc.blocks", bytes(b))
    return f"rlfc.blocks run {r}: byte {at - start} of the run"


def make_mutant(blob: bytes, seed: int) -> tuple[bytes, list[str]]:
    """A mutant of a valid file with valid checksums, and what was changed."""
    rng = np.random.default_rng(seed)
    meta, secs = split_file(blob)
    secs = list(secs)
    what = []
    for _ in range(int(rng.integers(1, 4))):
        k = int(rng.integers(10))
        if k < 3:
            what.append(mutate_meta(meta, rng))
        elif k == 3 and (d := mutate_run(meta, secs, rng)) is not None:
            what.append(d)
        elif k < 9 and secs:
            i = int(rng.integers(len(secs)))
            data, d = mutate_bytes(secs[i][1], rng)
            secs[i] = (secs[i][0], data)
            what.append(f"{secs[i][0]}: {d}")
        elif secs:
            i = int(rng.integers(len(secs)))
            op = int(rng.integers(3))
            if op == 0:
                what.append(f"drop section {secs.pop(i)[0]}")
            elif op == 1:
                j = int(rng.integers(len(secs)))
                secs[i], secs[j] = secs[j], secs[i]
                what.append(f"swap sections {i},{j}")
            else:
                j = int(rng.integers(len(secs)))
                what.append(f"section {secs[j][0]} := {secs[i][0]}")
                secs[j] = (secs[j][0], secs[i][1])
    try:
        mj = json.dumps(meta, allow_nan=False).encode()
    except (ValueError, TypeError):
        mj = b"{}"
    return b"".join(bytes(p) for p in build_container(mj, secs)), what


# -- decode every way ------------------------------------------------------------------------
def _sample_blocks(d, rng, k=12):
    n = d.rows * d.cols
    return (rng.integers(0, n, k), rng.integers(0, d.nby, k), rng.integers(0, d.nbx, k))


def decode_everything(blob: bytes, path: str, seed: int) -> dict:
    """Decode a file along every path; raises LfcError (typed), AssertionError (paths
    disagree) or anything else (a defect).

    Returns:
        {"levels": {level: full decode (rows, cols, H, W, C)}, "planes": {level: (N0, H, W, P)
        int32 planes} (tx files, for the JavaScript reference), "tx_version": int or None}.
    """
    from formats.lfcfile import open_lfc
    from formats.registry import open_decoder
    rng = np.random.default_rng(seed)
    files = [open_lfc(path), open_lfc(blob, name="<mutant>"),
             open_lfc(ByteRangeSource(lambda a, b: blob[a:b], len(blob)), name="<ranges>")]
    try:
        files[0].container.verify_all()
        decs = [open_decoder(f) for f in files]
        d = decs[0]
        out = {"levels": {}, "planes": {}, "tx_version": None}
        if f"{d.info().get('codec')}" == "lfn" or not hasattr(d, "nby"):
            if d.rows * d.cols * d.height * d.width > LFN_RENDER_PIXELS:
                # a network renders whatever size its metadata declares (up to the limits) at
                # ~1 µs a pixel: a mutant that declares a huge grid is checked on one view per
                # level (none where one view alone is huge); its parse is what is under test
                out["sampled"] = True
                if d.height * d.width <= LFN_RENDER_PIXELS:
                    for level in sorted({0, d.levels}):
                        r, c = int(rng.integers(d.rows)), int(rng.integers(d.cols))
                        one = d.decode_view(r, c, level)
                        assert np.array_equal(one, decs[1].decode_view(r, c, level)), "lfn mmap != buffer"
                        assert np.array_equal(one, decs[2].decode_view(r, c, level)), "lfn ranges != mmap"
                return out
            for level in sorted({0, d.levels}):
                ref = out["levels"][level] = d.decode_all(level)
                assert np.array_equal(ref, decs[1].decode_all(level)), "lfn mmap != buffer"
                r, c = int(rng.integers(d.rows)), int(rng.integers(d.cols))
                assert np.array_equal(ref[r, c], decs[2].decode_view(r, c, level)), "lfn view != all"
            return out
        tx = files[0].meta["config"].get("tx")            # a tx file: the JavaScript reader is its oracle
        if isinstance(tx, dict):
            out["tx_version"] = tx.get("version")
        from rlfc.torch_decode import TorchBlockDecoder
        B = d.block_size
        for level in sorted({0, d.levels}):
            full = out["levels"][level] = d.decode_all(level)
            if out["tx_version"] is not None:
                out["planes"][level] = d.decode_views(level=level, planes=True)
            assert full.shape == (d.rows, d.cols, d.height, d.width, d.channels) and full.dtype == d.dtype
            assert np.array_equal(full, decs[1].decode_all(level)), "mmap != buffer (full)"
            v, by, bx = _sample_blocks(d, rng)
            got = {"mmap": d.decode_blocks(v, by, bx, level), "ranges": decs[2].decode_blocks(v, by, bx, level)}
            got["torch"] = TorchBlockDecoder(d, "cpu").decode_blocks(v, by, bx, level)
            for name, blocks in got.items():
                assert np.array_equal(blocks, got["mmap"]), f"batched {name} != mmap"
            for i in range(min(4, v.size)):
                r, c = divmod(int(v[i]), d.cols)
                one = decs[2].decode_block(r, c, int(by[i]), int(bx[i]), level)
                h, w = one.shape[:2]
                crop = full[r, c, by[i] * B:by[i] * B + h, bx[i] * B:bx[i] * B + w]
                assert np.array_equal(one, crop), "single block != full"
                assert np.array_equal(got["mmap"][i, :h, :w], crop), "batched block != full"
            r, c = int(rng.integers(d.rows)), int(rng.integers(d.cols))
            assert np.array_equal(decs[2].decode_view(r, c, level), full[r, c]), "view != full"
        return out
    finally:
        for f in files:
            f.close()


def check_reference(blob: bytes, decoded: dict) -> bool:
    """Compare the library's decodes with :mod:`tools.refdecode` where it covers the file;
    raises AssertionError on any difference (or a reference refusal). True when compared."""
    from tools import refdecode
    if not refdecode.covers(blob):
        return False
    for level, got in decoded["levels"].items():
        try:
            ref = refdecode.ref_decode(blob, int(level))
        except refdecode.RefError as e:
            raise AssertionError(f"reference refuses level {level}: {e}") from None
        except Exception as e:  # noqa: BLE001 - a reference bug is still a disagreement to look at
            raise AssertionError(f"reference failed at level {level}: {type(e).__name__}: {e}") from None
        assert ref.shape == got.shape and ref.dtype == got.dtype, f"reference shape {ref.shape} != {got.shape}"
        diff = np.abs(ref.astype(np.int64) - got.astype(np.int64))
        lfn = json.loads(bytes(Container(blob).read("meta")))["codec"] == "lfn"
        tol = 1 if lfn else 0
        if lfn and diff.max(initial=0) > tol:
            _lfn_precision(blob, float(level), got, diff, tol)
        assert diff.max(initial=0) <= tol, f"reference differs at level {level}: {int((diff > tol).sum())} samples, " \
                                           f"up to {int(diff.max())}"
    return True


class IllConditioned(Exception):
    """An LFN mutant whose network float32 cannot evaluate to one grey level (its weights amplify
    rounding): the reference differs only where the library's own result moves as much when the
    same rays are evaluated in another batch size."""


#: at most this many differing pixels are re-rendered to measure float32's own spread there
LFN_SPREAD_PIXELS = 64


def _lfn_precision(blob: bytes, level: float, got: np.ndarray, diff: np.ndarray, tol: int) -> None:
    """Raise :class:`IllConditioned` when every sample where the float64 reference differs from
    the library by more than ``tol`` is one where the library itself moves by at least that much
    (less ``tol``) when its rays are rendered one per batch instead of together; else return
    (the caller reports the mismatch)."""
    from formats.lfcfile import open_lfc
    from formats.registry import open_decoder

    pix = np.argwhere((diff > tol).any(-1))                   # (k, 4): row, col, y, x
    if len(pix) > LFN_SPREAD_PIXELS:
        return
    with open_lfc(blob, name="<mutant>") as f:
        d = open_decoder(f)
        neurons = d.neurons_at(level)
        views = {}
        for r, c, y, x in pix.tolist():
            if (r, c) not in views:                            # the library's own decode, again
                views[r, c] = d.decode_view(r, c, level).astype(np.int64)
            together = views[r, c][y, x]
            if not np.array_equal(together, got[r, c, y, x]):
                return
            ray = d.view_rays(r, c).reshape(-1, 6)[y * d.width + x][None].astype(np.float32)
            alone = d.to_pixels(d.render_rays(ray, neurons, batch=1))[0].astype(np.int64)
            if np.any(diff[r, c, y, x] > tol + np.abs(alone - together)):
                return
    raise IllConditioned(f"level {level:g}: {len(pix)} pixel(s) up to {int(diff.max())} levels from the float64 "
                         f"reference, as far as the library's own float32 result moves with the batch size")


def run_one(blob: bytes, seed: int, workdir: str) -> tuple[str, str, dict | None]:
    """(outcome, detail, tx planes for the JavaScript reference or None) of decoding one mutant
    in this process."""
    from formats.errors import LfcError
    path = os.path.join(workdir, "mutant.lfc")
    with open(path, "wb") as fh:
        fh.write(blob)
    try:
        out = decode_everything(blob, path, seed)
        if out.get("sampled"):
            return "sampled", "", None
        if check_reference(blob, out):
            return "referenced", "", None
        return "exact", "", out["planes"] if out["tx_version"] in (2, 3, 4, 5, 6) else None
    except IllConditioned as e:
        return "illcond", str(e), None
    except LfcError as e:
        return "typed", type(e).__name__, None
    except AssertionError as e:
        return "mismatch", str(e), None
    except MemoryError:
        return "crash", "MemoryError", None
    except Exception as e:  # noqa: BLE001 - counting defects is the point
        tb = traceback.extract_tb(e.__traceback__)[-1]
        return "untyped", f"{type(e).__name__}: {e} at {Path(tb.filename).name}:{tb.lineno}", None


NODE = shutil.which("node")
WEB_DECODE = ROOT / "tools" / "web_decode.mjs"


def check_js(blob: bytes, planes: dict, workdir: str, timeout_s: float = 120.0) -> tuple[str, str]:
    """Decode a tx (versions 2 to 6) file with the JavaScript reader at every level and compare its
    int32 planes with the library's → ("referenced", "") or ("mismatch", why)."""
    path = os.path.join(workdir, "js.lfc")
    out = os.path.join(workdir, "js")
    shutil.rmtree(out, ignore_errors=True)
    with open(path, "wb") as fh:
        fh.write(blob)
    env = dict(os.environ, LFC_LEVELS=",".join(str(level) for level in sorted(planes)))
    try:
        got = subprocess.run([NODE, str(WEB_DECODE), path, out], capture_output=True, text=True, timeout=timeout_s,
                             env=env)
    except subprocess.TimeoutExpired:
        return "mismatch", f"JavaScript reader over {timeout_s:.0f} s"
    if got.returncode != 0:
        return "mismatch", "JavaScript reader crashed: " + got.stderr.strip().splitlines()[-1][:300]
    info = json.loads(got.stdout.strip().splitlines()[-1])
    if not info["ok"]:
        return "mismatch", f"JavaScript reader refuses: {info['name']}: {info['message'][:300]}"
    for level, py in planes.items():
        n, h, w, p = py.shape
        for v in range(n):
            name = f"view_{v}.bin" if level == 0 else f"view_{v}_L{level}.bin"
            js = np.fromfile(os.path.join(out, name), np.int32).reshape(info["Hp"], info["Wp"], info["P"])[:h, :w]
            if not np.array_equal(js, py[v]):
                return "mismatch", f"JavaScript reader differs: level {level} view {v}, {int((js != py[v]).sum())} samples"
    return "referenced", ""


# -- worker process --------------------------------------------------------------------------
def _worker(conn, mem_bytes: int, workdir: str) -> None:
    import torch
    torch.set_num_threads(1)
    if mem_bytes:
        resource.setrlimit(resource.RLIMIT_AS, (mem_bytes, mem_bytes))
    while True:
        job = conn.recv()
        if job is None:
            return
        blob, seed = job
        outcome, detail, planes = run_one(blob, seed, workdir)
        conn.send((outcome, detail, planes, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss))


class Runner:
    """Feeds mutants to a worker process under an address-space limit, restarting it after a
    crash or a hang."""

    def __init__(self, mem_mib: int = 3072, deadline_s: float = 60.0):
        self.mem = mem_mib << 20
        self.deadline = deadline_s
        self.ctx = mp.get_context("spawn")
        self.tmp = tempfile.TemporaryDirectory(prefix="lfcfuzz")
        self.proc = None
        self.peak_kib = 0

    def _start(self):
        self.conn, child = self.ctx.Pipe()
        self.proc = self.ctx.Process(target=_worker, args=(child, self.mem, self.tmp.name), daemon=True)
        self.proc.start()

    def run(self, blob: bytes, seed: int) -> tuple[str, str]:
        outcome, detail, planes = self._run(blob, seed)
        if planes and NODE:
            return check_js(blob, planes, self.tmp.name)
        return outcome, detail

    def _run(self, blob: bytes, seed: int) -> tuple[str, str, dict | None]:
        if self.proc is None or not self.proc.is_alive():
            self._start()
        self.conn.send((blob, seed))
        if not self.conn.poll(self.deadline):
            self.proc.kill()
            self.proc.join()
            self.proc = None
            return "hang", f"over {self.deadline:.0f} s", None
        try:
            outcome, detail, planes, rss = self.conn.recv()
        except EOFError:
            self.proc.join()
            code = self.proc.exitcode
            self.proc = None
            return "crash", f"worker exit code {code}", None
        self.peak_kib = max(self.peak_kib, rss)
        return outcome, detail, planes

    def close(self):
        if self.proc is not None and self.proc.is_alive():
            self.conn.send(None)
            self.proc.join(10)
        self.tmp.cleanup()


def fuzz(n: int | None = None, minutes: float | None = None, seed: int = 0, mem_mib: int = 3072,
         files: list[Path] | None = None, deadline_s: float = 60.0, log=None) -> dict:
    """Run ``n`` mutants (or as many as fit in ``minutes``), cycling over the corpus files.

    Returns:
        {"tried", "typed", "exact", "referenced", "untyped", "mismatch", "crash", "hang", "peak_rss_mib",
        "per_file": {...}, "defects": [{"file", "seed", "what", "outcome", "detail"}]}.
    """
    files = files or corpus_files()
    blobs = [(p.name, p.read_bytes()) for p in files]
    counts = dict.fromkeys(COUNTS, 0)
    per_file = {name: dict.fromkeys(COUNTS, 0) for name, _ in blobs}
    defects = []
    runner = Runner(mem_mib, deadline_s)
    t_end = time.monotonic() + 60 * minutes if minutes else None
    i = 0
    try:
        while (n is None or i < n) and (t_end is None or time.monotonic() < t_end):
            name, blob = blobs[i % len(blobs)]
            s = seed * 1_000_003 + i
            mutant, what = make_mutant(blob, s)
            outcome, detail = runner.run(mutant, s)
            for c in (counts, per_file[name]):
                c["tried"] += 1
                c["exact" if outcome in ("referenced", "sampled", "illcond") else outcome] += 1
                c["referenced"] += outcome == "referenced"
                c["sampled"] += outcome == "sampled"
                c["illcond"] += outcome == "illcond"
            if outcome in DEFECTS:
                defects.append({"file": name, "seed": s, "what": what, "outcome": outcome, "detail": detail})
            if outcome in DEFECTS + ("illcond",) and log:
                log(f"{outcome}: {name} seed {s} {what}: {detail}")
            i += 1
    finally:
        runner.close()
    return {**counts, "peak_rss_mib": round(runner.peak_kib / 1024, 1), "per_file": per_file, "defects": defects}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m tools.fuzz", description=__doc__.split("\n\n")[0])
    ap.add_argument("--minutes", type=float, default=None, help="run for this long (default: --count)")
    ap.add_argument("--count", type=int, default=None, help="mutants to try (default 500 without --minutes)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--mem-mib", type=int, default=3072, help="address-space limit of the worker (MiB)")
    ap.add_argument("--out", default=None, help="write the report as JSON here")
    a = ap.parse_args(argv)
    count = a.count if a.count is not None or a.minutes else 500
    rep = fuzz(n=count, minutes=a.minutes, seed=a.seed, mem_mib=a.mem_mib, log=print)
    summary = {k: rep[k] for k in COUNTS + ("peak_rss_mib",)}
    print(json.dumps(summary))
    if a.out:
        Path(a.out).write_text(json.dumps(rep, indent=1))
    return 1 if any(rep[k] for k in DEFECTS) else 0


if __name__ == "__main__":
    raise SystemExit(main())
