"""The rANS lane parser of tx block streams on a torch device: the same integers as
:func:`rlfc.txparse.parse_lanes`, so that a GPU decode parses its residual blocks where it
reconstructs them instead of on the host.

Two kernels decode the magnitude symbols, which are most of a stream:

- torch operations, step-major as the numpy parser (one step per symbol position over the
  lanes that still have symbols; ~30 small operations a step): any device, the reference;
- a Triton kernel, where Triton and a CUDA device are present: each lane decodes its own
  symbols in one loop (lanes sorted by length so that a program's lanes end together). One
  launch instead of tens of thousands; Triton ships with PyTorch's CUDA builds and is never
  required (``LFC_TRITON=0`` turns it off; a kernel that fails to build falls back to the torch
  steps for the rest of the process, the reason kept in ``_TRITON_FAILED``).

Everything else (modes, last positions, escape buckets, raw bits) is a few dozen vectorized
torch operations. Malformed streams raise :class:`~formats.errors.FormatError` as on the host;
indices that a malformed stream drives are clamped before every gather, so a bad stream never
reads outside a device array.
"""
from __future__ import annotations

import os

import numpy as np

from formats.errors import FormatError

from .rans import BACK_BITS, L as RANS_L, PROB_BITS, STATE_BYTES, Tables
from .txparse import slot_words, symbol_parts
from .txsyntax import _BAND8_ARR, _MASK, ESC, MODE_SKIP, N_BUCKETS, N_MODES, ctx_esc, ctx_last, ctx_mag, ctx_mode
from .xp import shared

_L2 = RANS_L >> 8          # a state under this needs two bytes in
MAX_DEVICE_SYMBOLS = 1 << 24   # magnitude symbols parsed together on a device (~1–2 GB of temporaries)


def device_words(tables: Tables, device):
    """:func:`rlfc.txparse.slot_words` as an int64 tensor on ``device``, cached on the tables."""
    import torch

    cache = tables.__dict__.setdefault("_device_words", {})
    key = str(device)
    if key not in cache:
        cache[key] = shared(torch.as_tensor(slot_words(tables).astype(np.int64), device=device))
    return cache[key]


_CONSTANTS: dict = {}


def _constants(pcs, device):
    """(plane classes (P,), band·8 per scan position (64,)) int64 tensors on ``device``, cached
    (a copy from the host waits for every kernel queued before it)."""
    import torch

    key = (str(device), tuple(int(c) for c in pcs))
    if key not in _CONSTANTS:
        _CONSTANTS[key] = shared(torch.as_tensor(np.asarray(pcs, np.int64), device=device),
                                 torch.as_tensor(_BAND8_ARR, device=device))
    return _CONSTANTS[key]


def pair_words(buf):
    """(N,) int64 tensor: byte i << 8 | byte i+1 of a uint8 tensor (the last byte paired with
    itself): one gather serves a decode step's one or two bytes in."""
    import torch

    b = buf.to(torch.int64)
    return (b << 8) | torch.cat([b[1:], b[-1:]])


def _step(words, w16, top, x, p, ctx):
    """One symbol of each lane (tensors ``x``, ``p``, ``ctx`` alike): (symbol, x, p)."""
    w = words[(ctx << PROB_BITS) | (x & _MASK)]
    x = ((w >> 7) & 0x1FFF) * (x >> PROB_BITS) + (w >> 20)
    n = (x < RANS_L).long() + (x < _L2).long()
    sh = n << 3
    x = (x << sh) | (w16[p.clamp(max=top)] >> (16 - sh))
    return w & 127, x, p + n


def parse_lanes_torch(buf, w16, starts, ends, tables: Tables, nt: int, pcs: np.ndarray, kind, key, name: str = "",
                      triton: bool | None = None, max_symbols: int | None = None):
    """Parse S streams at once on ``buf``'s device.

    Args:
        buf: (N,) uint8 tensor holding the streams, 8 bytes of slack after the last.
        w16: :func:`pair_words` of ``buf``.
        starts, ends, kind, key: (S,) int64 tensors on the same device: stream i is
            ``buf[starts[i]:ends[i]]``, its view kind (0/1) and key flag (0/1).
        pcs: (P,) numpy plane classes.
        triton: use the Triton magnitude kernel (None: where it is available and the device is
            CUDA, unless ``LFC_TRITON=0``).
        max_symbols: magnitude symbols parsed together (default :data:`MAX_DEVICE_SYMBOLS`);
            streams that claim more are parsed in runs of lanes of at most that many, as the
            numpy parser does.

    Returns:
        (modes (S, nt) int64, index (K,) int64, values (K,) int64) tensors, as
        :class:`rlfc.txparse.Parsed` holds them (index into the flat (S, nt, P, 64) scan-order
        levels, ascending).

    Raises:
        FormatError: a stream that is malformed (bad symbol, overrun, wrong end state).
    """
    import torch

    dev = buf.device
    S, P = int(starts.numel()), len(pcs)
    i64 = dict(dtype=torch.int64, device=dev)
    if S == 0:
        z = torch.zeros(0, **i64)
        return torch.zeros((0, nt), **i64), z, z
    words = device_words(tables, dev)
    top = int(buf.numel()) - 1
    x = torch.zeros(S, **i64)
    for i in range(STATE_BYTES):                                        # the start state, little-endian
        x |= buf[(starts + i).clamp(max=top)].to(torch.int64) << (8 * i)
    p = starts + STATE_BYTES
    # tb modes, then the last position of every (tb, plane) not skipped
    modes = torch.zeros((S, nt), **i64)
    prev = torch.full((S,), 3, **i64)
    for t in range(nt):
        s, x, p = _step(words, w16, top, x, p, ctx_mode(kind, prev))
        modes[:, t] = s
        prev = s.clamp(max=3)
    last = torch.zeros((S, nt, P), **i64)         # (an undefined mode counts as coded here; refused below)
    for t in range(nt):
        act = modes[:, t] != MODE_SKIP
        for pi in range(P):
            s, xn, pn = _step(words, w16, top, x, p, ctx_last(int(pcs[pi]), modes[:, t], key))
            x, p = torch.where(act, xn, x), torch.where(act, pn, p)
            last[:, t, pi] = torch.where(act, s, 0)
    # magnitudes: per lane, groups g = (lane, t, p) in order, each of length last; symbol j of a
    # group is at scan position last − 1 − j (lane-major, as the numpy parser)
    flat_len = last.reshape(-1)
    G = flat_len.numel()
    cs = torch.cumsum(flat_len, 0)
    bad_mode, bad_last, tot = torch.stack([(modes >= N_MODES).any(), (last > 64).any(), cs[-1]]).tolist()  # one sync
    if bad_mode:
        raise FormatError(f"{name}: tx block has an undefined tb mode")
    if bad_last:
        raise FormatError(f"{name}: tx block has a last position past 64")
    per_lane = last.reshape(S, nt * P).sum(1)
    budget = MAX_DEVICE_SYMBOLS if max_symbols is None else max_symbols
    if tot > budget and S > 1:                    # bounded temporaries, whatever the streams claim
        bounds = symbol_parts(per_lane.cpu().numpy(), budget)
        parts = [parse_lanes_torch(buf, w16, starts[a:b], ends[a:b], tables, nt, pcs, kind[a:b], key[a:b], name,
                                   triton, budget) for a, b in zip(bounds[:-1], bounds[1:])]
        per = nt * P * 64
        return (torch.cat([m for m, _, _ in parts]),
                torch.cat([i + a * per for (_, i, _), a in zip(parts, bounds[:-1])]),
                torch.cat([v for _, _, v in parts]))
    lane_start = torch.cumsum(per_lane, 0) - per_lane
    # per group first (S·nt·P of them), then one gather per symbol: the symbols outnumber the
    # groups ~10 to 1, and int64 division on a GPU is slow
    pcs_t, band8 = _constants(pcs, dev)
    g = torch.arange(G, **i64)
    g_lane = g // (nt * P)
    g_pc = pcs_t.repeat(S * nt)
    g_ctx = ctx_mag(g_pc, 0, key[g_lane], 0)
    g_of = torch.repeat_interleave(g, flat_len, output_size=tot)
    j = torch.arange(tot, **i64) - (cs - flat_len)[g_of]
    index = ((g << 6) + flat_len - 1)[g_of] - j                       # g·64 + position: ascending
    ctx1 = g_ctx[g_of] + band8[index & 63] + (j >= 1)
    jm = j.clamp(max=2)
    got = None
    if (_triton_wanted(dev) if triton is None else triton) and not _TRITON_FAILED:
        try:
            got = _magnitudes_triton(words, w16, top, x, p, ctx1, jm, per_lane, lane_start)
        except Exception as e:            # a Triton or driver that cannot build the kernel: torch steps
            _TRITON_FAILED.append(f"{type(e).__name__}: {e}")
    sym, x, p = got or _magnitudes_steps(words, w16, top, x, p, ctx1, jm, per_lane, lane_start, g_lane[g_of])
    if tot and int(sym.max()) > ESC:
        raise FormatError(f"{name}: tx block has an undefined magnitude symbol")
    # escapes (symbol ESC: |c| >= ESC + first), a lane's in order after its magnitudes
    esc = torch.nonzero(sym == ESC).reshape(-1)
    E = int(esc.numel())
    buckets = torch.zeros(E, **i64)
    e_grp = g_of[esc]
    e_lane = g_lane[e_grp]
    if E:
        ec = torch.bincount(e_lane, minlength=S)
        col = torch.arange(E, **i64) - (torch.cumsum(ec, 0) - ec)[e_lane]      # k-th escape of its lane
        by_col = torch.argsort(col, stable=True)
        ncol = torch.bincount(col).tolist()
        e_ctx = ctx_esc(g_pc[e_grp])
        a = 0
        for n in ncol:
            sel = by_col[a:a + n]
            a += n
            ln = e_lane[sel]
            s, xn, pn = _step(words, w16, top, x[ln], p[ln], e_ctx[sel])
            x[ln], p[ln] = xn, pn
            buckets[sel] = s
        if bool(((buckets >= N_BUCKETS) | (buckets > 40)).any()):
            raise FormatError(f"{name}: tx block has an undefined escape bucket")
    # raw bits: signs then escape suffixes, per lane
    first = j == 0
    nz = (sym > 0) | first
    sidx = torch.nonzero(nz).reshape(-1)
    s_lane = g_lane[g_of[sidx]]
    nsign = torch.bincount(s_lane, minlength=S)
    nsuf = torch.zeros(S, **i64).index_add_(0, e_lane, buckets)
    nbits = nsign + nsuf
    kb = nbits.clamp(max=BACK_BITS)
    raw_start = ends - (nbits - kb + 7) // 8
    r = x - RANS_L
    ok = (r >= 0) & (r < (1 << kb)) & (p == raw_start) & (raw_start >= starts + STATE_BYTES)
    if not bool(ok.all()):
        raise FormatError(f"{name}: tx block stream is malformed (its symbols do not end where its raw bits start)")
    soff = torch.arange(sidx.numel(), **i64) - (torch.cumsum(nsign, 0) - nsign)[s_lane]
    sbit = _raw_bits(buf, top, raw_start[s_lane], r[s_lane], kb[s_lane], soff)
    vals = sym[sidx] + first[sidx].long()
    if E:
        eoff = nsign[e_lane] + (torch.cumsum(buckets, 0) - buckets) - (torch.cumsum(nsuf, 0) - nsuf)[e_lane]
        suffix = torch.zeros(E, **i64)
        rs, rb, kbe = raw_start[e_lane], r[e_lane], kb[e_lane]
        for b in range(int(buckets.max())):
            bit = _raw_bits(buf, top, rs, rb, kbe, eoff + b)
            suffix |= torch.where(buckets > b, bit << b, 0)
        vals[(torch.cumsum(nz.long(), 0) - 1)[esc]] = ESC + first[esc].long() + ((1 << buckets) - 1) + suffix
    return modes, index[sidx], torch.where(sbit == 1, -vals, vals)


def _raw_bits(buf, top, start, back, kb, off):
    """Raw bit ``off`` of each lane: bits below ``kb`` from the start state's R (``back``),
    the others from the stored bits at byte ``start`` (LSB-first); as the numpy parser."""
    stored = (off - kb).clamp(min=0)
    byte = buf[(start + stored // 8).clamp(0, top)].long()
    return (back >> off.clamp(0, 62)).bitwise_and(1).where(off < kb, (byte >> (stored & 7)) & 1)


def _magnitudes_steps(words, w16, top, x, p, ctx1, jm, per_lane, lane_start, lane):
    """The magnitude symbols (lane-major) in torch steps: lanes ranked by their number of
    symbols, longest first, so that the lanes active at step k are ranks [0, m_k) and every
    step reads and writes contiguous slices (as :func:`rlfc.txparse._magnitudes`)."""
    import torch

    dev = x.device
    tot, S = int(ctx1.numel()), int(per_lane.numel())
    sym = torch.zeros(tot, dtype=torch.int64, device=dev)
    if tot == 0:
        return sym, x, p
    order = torch.argsort(-per_lane, stable=True)
    rank = torch.empty_like(order)
    rank[order] = torch.arange(S, device=dev)
    lens = per_lane[order]
    K = int(lens[0])
    cnt = torch.searchsorted(-lens, -torch.arange(K, device=dev), side="left")     # lanes with more than k symbols
    offs = torch.cumsum(cnt, 0) - cnt
    sm = offs[torch.arange(tot, device=dev) - lane_start[lane]] + rank[lane]        # lane-major → step-major
    c1 = torch.empty_like(ctx1)
    c1[sm] = ctx1
    jj = torch.empty_like(jm)
    jj[sm] = jm
    g1, g2, first = (jj >= 1).long(), (jj == 2).long(), jj == 0
    nz = torch.zeros(tot, dtype=torch.int64, device=dev)
    xs, ps = x[order].clone(), p[order].clone()
    sm_sym = torch.empty(tot, dtype=torch.int64, device=dev)
    offl, cntl = offs.tolist(), cnt.tolist()
    for k, (o, m) in enumerate(zip(offl, cntl)):
        c = c1[o:o + m]
        if k >= 1:
            o1 = offl[k - 1]
            c = c + nz[o1:o1 + m] * g1[o:o + m]
            if k >= 2:
                o2 = offl[k - 2]
                c = c + nz[o2:o2 + m] * g2[o:o + m]
        s, xs[:m], ps[:m] = _step(words, w16, top, xs[:m], ps[:m], c)
        sm_sym[o:o + m] = s
        nz[o:o + m] = ((s > 0) | first[o:o + m]).long()
    sym = sm_sym[sm]
    x, p = x.clone(), p.clone()
    x[order], p[order] = xs, ps
    return sym, x, p


#: why the Triton kernel failed, once it has (the process then parses in torch steps)
_TRITON_FAILED: list = []


def _triton_wanted(device) -> bool:
    if device.type != "cuda" or os.environ.get("LFC_TRITON", "1") == "0":
        return False
    try:
        import triton  # noqa: F401
    except ImportError:
        return False
    return True


_KERNEL = None


def _magnitude_kernel():
    """The Triton kernel (built on first use: importing Triton costs ~1 s)."""
    global _KERNEL
    if _KERNEL is None:
        import triton
        import triton.language as tl

        @triton.jit
        def kernel(cj_ptr, perm_ptr, start_ptr, len_ptr, kmax_ptr, x_ptr, p_ptr, words_ptr, w16_ptr, sym_ptr, S, top,
                   BLOCK: tl.constexpr):
            pid = tl.program_id(0)
            r = pid * BLOCK + tl.arange(0, BLOCK)
            ok = r < S
            ln = tl.load(perm_ptr + r, mask=ok, other=0)
            st = tl.load(start_ptr + ln, mask=ok, other=0)
            n_sym = tl.load(len_ptr + ln, mask=ok, other=0)
            x = tl.load(x_ptr + ln, mask=ok, other=0)
            p = tl.load(p_ptr + ln, mask=ok, other=0)
            n1 = tl.zeros([BLOCK], dtype=tl.int64)
            n2 = tl.zeros([BLOCK], dtype=tl.int64)
            kmax = tl.load(kmax_ptr + pid)                               # the program's longest lane
            k = 0
            while k < kmax:
                act = k < n_sym
                i = st + k
                cj = tl.load(cj_ptr + i, mask=act, other=0)        # context without neighbours | jm << 32
                jm = cj >> 32
                c = (cj & 0xFFFFFFFF) + n1 * (jm >= 1).to(tl.int64) + n2 * (jm == 2).to(tl.int64)
                w = tl.load(words_ptr + ((c << 12) | (x & 4095)), mask=act, other=0)
                xn = ((w >> 7) & 0x1FFF) * (x >> 12) + (w >> 20)
                n = (xn < 32768).to(tl.int64) + (xn < 128).to(tl.int64)
                sh = n * 8
                b = tl.load(w16_ptr + tl.minimum(p, top), mask=act, other=0)
                xn = (xn << sh) | (b >> (16 - sh))
                s = w & 127
                nz = ((s > 0) | (jm == 0)).to(tl.int64)
                x = tl.where(act, xn, x)
                p = tl.where(act, p + n, p)
                n2 = tl.where(act, n1, n2)
                n1 = tl.where(act, nz, n1)
                tl.store(sym_ptr + i, s, mask=act)
                k += 1
            tl.store(x_ptr + ln, x, mask=ok)
            tl.store(p_ptr + ln, p, mask=ok)

        _KERNEL = kernel
    return _KERNEL


TRITON_BLOCK = 128


def _magnitudes_triton(words, w16, top, x, p, ctx1, jm, per_lane, lane_start):
    """The magnitude symbols (lane-major) by the Triton kernel: one program per
    :data:`TRITON_BLOCK` lanes of similar length, each lane looping over its own symbols."""
    import torch

    assert RANS_L == 32768 and _L2 == 128 and PROB_BITS == 12   # the kernel's constants
    S, tot = int(per_lane.numel()), int(ctx1.numel())
    sym = torch.zeros(tot, dtype=torch.int64, device=x.device)
    if tot == 0:
        return sym, x, p
    perm = torch.argsort(per_lane, descending=True)
    x, p = x.contiguous().clone(), p.contiguous().clone()
    cj = (ctx1 | (jm << 32)).contiguous()
    kmax = per_lane[perm[::TRITON_BLOCK]].contiguous()                 # each program's first lane is its longest
    grid = (int(kmax.numel()),)
    _magnitude_kernel()[grid](cj, perm, lane_start.contiguous(), per_lane.contiguous(), kmax, x, p, words, w16, sym, S,
                              top, BLOCK=TRITON_BLOCK)
    return sym, x, p
