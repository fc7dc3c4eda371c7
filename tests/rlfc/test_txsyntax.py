"""tx block syntax: symbols → streams → lanes parser == reference parser == the input, and
the compact tables round-trip; malformed streams raise FormatError."""
import threading

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from formats.errors import FormatError
from rlfc import txparse as px, txparse_one as p1, txsyntax as tx


def _random_blocks(rng, S, nt, P, density, big):
    modes = rng.integers(0, 3, (S, nt))
    levels = np.zeros((S, nt, P, 64), np.int64)
    for s in range(S):
        for t in range(nt):
            for p in range(P):
                n = int(rng.integers(0, 65)) if rng.random() < density else 0
                pos = rng.choice(64, n, replace=False)
                mag = rng.geometric(0.4, n) if not big else rng.integers(1, 2 ** 21, n)
                levels[s, t, p, pos] = mag * rng.choice([-1, 1], n)
    levels[modes == 0] = 0
    return modes, levels


def _encode(modes, levels, kind, key, pcs):
    lane, ctx, sym, rl, rb = tx.block_symbols(modes, levels, kind, key, pcs)
    q = tx.quantize_counts(tx.count_symbols(ctx, sym))
    q2 = tx.tables_from_bytes(tx.tables_to_bytes(q), "x")
    assert (q2 == q).all()
    tables = tx.tables_from_quantized(q2)
    return tx.pack_streams(len(modes), lane, ctx, sym, rl, rb, tables), tables


def _packed(streams):
    """(buffer of the streams back to back with 8 bytes of slack, (S + 1,) int64 starts)."""
    starts = np.concatenate([[0], np.cumsum([len(b) for b in streams])]).astype(np.int64)
    return np.frombuffer(b"".join(streams) + bytes(8), np.uint8), starts


@settings(max_examples=40)
@given(st.integers(0, 2 ** 31), st.integers(1, 60), st.sampled_from([1, 4]), st.sampled_from([1, 2, 3, 4]),
       st.floats(0, 1), st.booleans(), st.sampled_from([0, 3, 32, 10 ** 6]))
def test_streams_parse_back_exactly(seed, S, nt, P, density, big, tail):
    """Lanes parse back exactly whichever step the magnitudes switch to plain Python at (tail
    = TAIL_LANES: 0 never, 10**6 from the first step), and one by one."""
    rng = np.random.default_rng(seed)
    modes, levels = _random_blocks(rng, S, nt, P, density, big)
    kind, key, pcs = rng.integers(0, 2, S), rng.integers(0, 2, S), tx.plane_classes(P)
    streams, tables = _encode(modes, levels, kind, key, pcs)
    buf, starts = _packed(streams)
    old = px.TAIL_LANES
    try:
        px.TAIL_LANES = tail
        got = px.parse_lanes(buf, starts[:-1], starts[1:], tables, nt, pcs, kind, key)
    finally:
        px.TAIL_LANES = old
    assert (got.modes == modes).all() and (got.levels == levels).all()
    ones = []
    for i in range(S):
        one = p1.parse_one(streams[i], tables, nt, pcs, int(kind[i]), int(key[i]))
        assert (one.modes[0] == modes[i]).all() and (one.levels[0] == levels[i]).all()
        ones.append(one)
    cat = px.concat_parsed(ones)                      # the scalar path of a few streams, joined
    assert (cat.modes == modes).all() and (cat.levels == levels).all()


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2 ** 31), st.integers(1, 40), st.sampled_from([1, 4, 9]), st.sampled_from([1, 2, 3, 4]),
       st.floats(0, 1), st.booleans())
def test_counts_only_are_the_packed_symbols_counts(seed, S, nt, P, density, big):
    """The rate search's counts (``counts_only``: no order, lanes or raw bits) equal the counts
    of the symbols the packer codes, escapes and last position 64 included, levels under a skip
    mode ignored as the packer ignores them."""
    rng = np.random.default_rng(seed)
    modes, levels = _random_blocks(rng, S, nt, P, density, big)
    levels[rng.random((S, nt, P, 64)) < 0.02] = 17                # full tbs, escapes of the first
    levels[:, :, :, 63][rng.random((S, nt, P)) < 0.3] = -40       # symbol, and levels under skips
    kind, key, pcs = rng.integers(0, 2, S), rng.integers(0, 2, S), tx.plane_classes(P)
    lane, ctx, sym, rl, rb = tx.block_symbols(modes, levels, kind, key, pcs)
    assert np.array_equal(tx.block_symbols(modes, levels, kind, key, pcs, counts_only=True),
                          tx.count_symbols(ctx, sym))


@pytest.mark.parametrize("tail", [0, 32, 10 ** 6])
def test_malformed_streams_raise(tail, monkeypatch):
    monkeypatch.setattr(px, "TAIL_LANES", tail)
    rng = np.random.default_rng(1)
    modes, levels = _random_blocks(rng, 20, 4, 3, 0.5, False)
    modes[:, 0] = 1
    levels[:, 0, 0, 0] = 3                                  # every stream has symbols and raw bits
    kind, key, pcs = np.zeros(20, int), np.zeros(20, int), tx.plane_classes(3)
    streams, tables = _encode(modes, levels, kind, key, pcs)
    for cut in (lambda b: b[:-1], lambda b: b + b"\x00", lambda b: bytes([b[0] ^ 0x55]) + b[1:]):
        bad = [cut(b) for b in streams]
        buf, starts = _packed(bad)
        with pytest.raises(FormatError):
            px.parse_lanes(buf, starts[:-1], starts[1:], tables, 4, pcs, kind, key)
        with pytest.raises(FormatError):
            for b in bad:
                p1.parse_one(b, tables, 4, pcs, 0, 0)
    with pytest.raises(FormatError):
        tx.tables_from_bytes(b"\x78\x9c\x03\x00\x00\x00\x00\x01", "x")


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2 ** 31), st.sampled_from([1, 4]), st.sampled_from([1, 3, 4]), st.booleans(),
       st.integers(1, 4), st.sampled_from(["flip", "cut", "extend"]), st.sampled_from([0, 32]))
def test_one_stream_parser_and_lanes_agree_on_damaged_streams(seed, nt, P, big, hits, how, tail):
    """Damaged streams (bytes changed, cut short or lengthened): the one-stream parser and the
    lanes parser both refuse a stream with a FormatError, or both give the same syntax (a
    damaged stream may still be a valid one); the lanes' symbols in numpy steps throughout
    (tail 0) or, a single lane being under TAIL_LANES, in the plain-Python tail."""
    old_tail = px.TAIL_LANES
    px.TAIL_LANES = tail
    try:
        _damaged_agree(seed, nt, P, big, hits, how)
    finally:
        px.TAIL_LANES = old_tail


def _damaged_agree(seed, nt, P, big, hits, how):
    rng = np.random.default_rng(seed)
    modes, levels = _random_blocks(rng, 6, nt, P, 0.7, big)
    kind, key, pcs = rng.integers(0, 2, 6), rng.integers(0, 2, 6), tx.plane_classes(P)
    streams, tables = _encode(modes, levels, kind, key, pcs)
    for i, b in enumerate(streams):
        b = bytearray(b)
        if how == "flip":
            for _ in range(hits):
                b[int(rng.integers(0, len(b)))] ^= int(rng.integers(1, 256))
        elif how == "cut":
            b = b[:max(0, len(b) - hits)]
        else:
            b += bytes(rng.integers(0, 256, hits).astype(np.uint8))
        b = bytes(b)
        try:
            one = p1.parse_one(b, tables, nt, pcs, int(kind[i]), int(key[i]))
        except FormatError:
            one = None
        buf, starts = _packed([b])
        try:
            lanes = px.parse_lanes(buf, starts[:-1], starts[1:], tables, nt, pcs, kind[i:i + 1], key[i:i + 1])
        except FormatError:
            lanes = None
        assert (one is None) == (lanes is None)
        if one is not None:
            assert (one.modes == lanes.modes).all() and (one.levels == lanes.levels).all()


@settings(max_examples=15)
@given(st.integers(0, 2 ** 31), st.integers(2, 25), st.integers(1, 3000))
def test_streams_packed_in_groups_are_the_same_bytes(seed, S, cells):
    """pack_streams codes lanes in groups to bound memory; no byte may depend on the grouping."""
    rng = np.random.default_rng(seed)
    modes, levels = _random_blocks(rng, S, 4, 3, 0.5, False)
    kind, key, pcs = rng.integers(0, 2, S), rng.integers(0, 2, S), tx.plane_classes(3)
    lane, ctx, sym, rl, rb = tx.block_symbols(modes, levels, kind, key, pcs)
    tables = tx.tables_from_quantized(tx.quantize_counts(tx.count_symbols(ctx, sym)))
    whole = tx._pack_group(S, lane, ctx, sym, rl, rb, tables)
    old = tx.PACK_CELLS
    try:
        tx.PACK_CELLS = cells
        assert tx.pack_streams(S, lane, ctx, sym, rl, rb, tables) == whole
    finally:
        tx.PACK_CELLS = old


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2 ** 32 - 1), C=st.integers(1, 6), A=st.integers(1, 128))
def test_slot_words_are_symbol_freq_and_offset_per_slot(seed, C, A):
    """One look-up word per (context, slot): symbol | freq << 7 | (slot − cum) << 20, checked
    against the tables' own slot, freq and cum arrays (sparse and full alphabets)."""
    from rlfc.rans import M, Tables

    rng = np.random.default_rng(seed)
    counts = np.where(rng.random((C, A)) < 0.4, rng.integers(1, 1000, (C, A)), 0)
    t = Tables.from_counts(counts)
    w = px.slot_words(t).reshape(C, M).astype(np.int64)
    ci = np.arange(C)[:, None]
    s = t.slot.astype(np.int64)
    assert (w & 127 == s).all()
    assert ((w >> 7) & 0x1FFF == t.freq[ci, s]).all()
    assert (w >> 20 == np.arange(M)[None, :] - t.cum[ci, s]).all()


def _device_parse(streams, tables, nt, pcs, kind, key, triton=False):
    """parse_lanes_torch on the CPU device: (modes, index, values) as numpy."""
    import torch

    from rlfc.txparse_torch import pair_words, parse_lanes_torch

    packed, starts = _packed(streams)
    buf = torch.as_tensor(packed.copy())
    t = [torch.as_tensor(np.asarray(a, np.int64)) for a in (starts[:-1], starts[1:], kind, key)]
    m, i, v = parse_lanes_torch(buf, pair_words(buf), t[0], t[1], tables, nt, pcs, t[2], t[3], "x", triton)
    return m.numpy(), i.numpy(), v.numpy()


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2 ** 31), st.integers(1, 60), st.sampled_from([1, 4]), st.sampled_from([1, 2, 3, 4]),
       st.floats(0, 1), st.booleans())
def test_device_parser_equals_the_numpy_parser(seed, S, nt, P, density, big):
    """The torch lanes parser (a GPU decode's) gives the numpy parser's modes, indices and
    values, escapes of every bucket included; a mutated stream raises or parses as numpy does."""
    rng = np.random.default_rng(seed)
    modes, levels = _random_blocks(rng, S, nt, P, density, big)
    kind, key, pcs = rng.integers(0, 2, S), rng.integers(0, 2, S), tx.plane_classes(P)
    streams, tables = _encode(modes, levels, kind, key, pcs)
    m, i, v = _device_parse(streams, tables, nt, pcs, kind, key)
    ref = px.Parsed(m, i, v, P)
    assert (ref.modes == modes).all() and (ref.levels == levels).all()
    k = int(rng.integers(0, S))
    b = bytearray(streams[k])
    b[int(rng.integers(0, len(b)))] ^= int(rng.integers(1, 256))
    bad = streams[:k] + [bytes(b)] + streams[k + 1:]
    buf, starts = _packed(bad)
    try:
        want = px.parse_lanes(buf, starts[:-1], starts[1:], tables, nt, pcs, kind, key)
    except FormatError:
        with pytest.raises(FormatError):
            _device_parse(bad, tables, nt, pcs, kind, key)
    else:
        m, i, v = _device_parse(bad, tables, nt, pcs, kind, key)
        assert (m == want.modes).all() and (i == want.index).all() and (v == want.values).all()


def test_device_parser_refuses_malformed_streams():
    rng = np.random.default_rng(1)
    modes, levels = _random_blocks(rng, 20, 4, 3, 0.5, False)
    modes[:, 0] = 1
    levels[:, 0, 0, 0] = 3
    kind, key, pcs = np.zeros(20, int), np.zeros(20, int), tx.plane_classes(3)
    streams, tables = _encode(modes, levels, kind, key, pcs)
    for cut in (lambda b: b[:-1], lambda b: b + b"\x00", lambda b: bytes([b[0] ^ 0x55]) + b[1:]):
        with pytest.raises(FormatError):
            _device_parse([cut(b) for b in streams], tables, 4, pcs, kind, key)


def test_triton_magnitude_kernel_equals_the_numpy_parser():
    """The Triton kernel of a CUDA decode, run by Triton's interpreter on the CPU (where Triton
    is installed; CI has none, and a lent GPU runs it compiled: tools/bench_gpu_decode)."""
    pytest.importorskip("triton")
    import os

    if os.environ.get("TRITON_INTERPRET") != "1":
        pytest.skip("needs TRITON_INTERPRET=1 (set before Triton is imported) on a machine without CUDA")
    rng = np.random.default_rng(5)
    for S, nt, P, density, big in [(40, 4, 3, 0.6, False), (7, 1, 1, 1.0, True), (300, 4, 2, 0.2, False)]:
        modes, levels = _random_blocks(rng, S, nt, P, density, big)
        kind, key, pcs = rng.integers(0, 2, S), rng.integers(0, 2, S), tx.plane_classes(P)
        streams, tables = _encode(modes, levels, kind, key, pcs)
        m, i, v = _device_parse(streams, tables, nt, pcs, kind, key, triton=True)
        got = px.Parsed(m, i, v, P)
        assert (got.modes == modes).all() and (got.levels == levels).all()


def test_a_triton_kernel_that_fails_to_build_falls_back_to_torch_steps(monkeypatch):
    """Triton is optional: a kernel that cannot be built (old GPU, broken toolchain) leaves the
    parse to the torch steps, the same integers, and says why."""
    import rlfc.txparse_torch as tp

    def broken():
        raise RuntimeError("no compiler for this GPU")

    monkeypatch.setattr(tp, "_magnitude_kernel", broken)
    monkeypatch.setattr(tp, "_TRITON_FAILED", [])
    rng = np.random.default_rng(3)
    modes, levels = _random_blocks(rng, 30, 4, 3, 0.7, False)
    kind, key, pcs = rng.integers(0, 2, 30), rng.integers(0, 2, 30), tx.plane_classes(3)
    streams, tables = _encode(modes, levels, kind, key, pcs)
    got = px.Parsed(*_device_parse(streams, tables, 4, pcs, kind, key, triton=True), 3)
    assert (got.modes == modes).all() and (got.levels == levels).all()
    assert tp._TRITON_FAILED == ["RuntimeError: no compiler for this GPU"]


@settings(max_examples=60)
@given(st.lists(st.integers(0, 800), min_size=1, max_size=50), st.integers(1, 3000))
def test_symbol_parts_cover_the_lanes_in_runs_within_the_budget(per_lane, budget):
    n = np.array(per_lane, np.int64)
    b = px.symbol_parts(n, budget)
    assert b[0] == 0 and b[-1] == n.size and all(x < y for x, y in zip(b, b[1:]))
    for a, c in zip(b, b[1:]):
        assert c - a == 1 or n[a:c].sum() <= budget
        if c < n.size:                                  # a run stops only where the next lane would not fit
            assert n[a:c + 1].sum() > budget


@pytest.mark.parametrize("device", [False, True])
def test_streams_that_claim_many_symbols_parse_in_bounded_runs(device, monkeypatch):
    """However many magnitude symbols the streams' last positions claim (a few bytes can claim
    768 per block), one magnitude pass handles at most the budget; the integers are the same."""
    import rlfc.txparse_torch as tp

    rng = np.random.default_rng(11)
    S, nt, P = 40, 4, 3
    modes, levels = _random_blocks(rng, S, nt, P, 0.9, False)
    kind, key, pcs = rng.integers(0, 2, S), rng.integers(0, 2, S), tx.plane_classes(P)
    streams, tables = _encode(modes, levels, kind, key, pcs)
    budget = int((levels != 0).sum() // 5)
    sizes = []
    if device:
        real = tp._magnitudes_steps
        monkeypatch.setattr(tp, "_magnitudes_steps", lambda *a: sizes.append(int(a[5].numel())) or real(*a))
        monkeypatch.setattr(tp, "MAX_DEVICE_SYMBOLS", budget)
        got = px.Parsed(*_device_parse(streams, tables, nt, pcs, kind, key), P)
    else:
        real = px._magnitudes
        monkeypatch.setattr(px, "_magnitudes", lambda *a: sizes.append(int(a[-1].size)) or real(*a))
        monkeypatch.setattr(px, "MAX_PARSE_SYMBOLS", budget)
        buf, starts = _packed(streams)
        got = px.parse_lanes(buf, starts[:-1], starts[1:], tables, nt, pcs, kind, key)
    assert (got.modes == modes).all() and (got.levels == levels).all()
    assert len(sizes) >= 5 and max(sizes) <= budget and sum(sizes) >= (levels != 0).sum()


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(1, 12), st.integers(1, 4), st.integers(1, 4), st.integers(0, 20))
def test_taking_lanes_gives_their_coefficients(seed, S, nt, P, n):
    """``Parsed.take`` (lanes in any order, repeats too; with the bounds kept or not) holds the
    dense levels of those lanes, and ``lane_bounds`` delimits each lane's coefficients."""
    rng = np.random.default_rng(seed)
    levels = rng.integers(-3, 4, (S, nt, P, 64)) * (rng.random((S, nt, P, 64)) < rng.random())
    levels[rng.random(S) < 0.3] = 0                                    # lanes without coefficients
    p = px.Parsed.from_levels(rng.integers(0, 3, (S, nt)), levels)
    per = nt * P * 64
    b = p.lane_bounds()
    assert b[0] == 0 and b[-1] == p.index.size and (np.diff(b) >= 0).all()
    for i in range(S):
        assert ((p.index[b[i]:b[i + 1]] // per) == i).all()
    lanes = rng.integers(0, S, n)
    for got in (p.take(lanes), p.take(lanes, b)):
        assert got.P == P and (got.modes == p.modes[lanes]).all()
        assert (got.levels == levels[lanes]).all()


def test_the_one_type_step_is_the_rans_step_on_every_state():
    """:func:`rlfc.txparse._step` (uint32 operands, a branchless two-byte renormalization read as
    byte pairs) against the textbook decode step in Python ints: x = freq·(x >> 12) + slot −
    cum, then a byte in while x < L, at most two (as every parser reads). States drawn over
    everything a stream's three state bytes can hold (0 and values past 256·L included, as a
    damaged stream gives), contexts over the whole table, and the pointers near the end of the
    bytes, where the pairs read the zeros past them."""
    from rlfc.rans import L, PROB_BITS, Tables

    rng = np.random.default_rng(7)
    C, A, n = 6, 9, 4000
    freq = np.zeros((C, A), np.int64)
    for c in range(C):                                   # rows summing to M, some symbols absent
        w = rng.random(A) * (rng.random(A) < 0.8) + 1e-9
        f = np.maximum(np.floor(w / w.sum() * 4096).astype(np.int64), 0)
        f[np.argmax(f)] += 4096 - f.sum()
        freq[c] = f
    tables = Tables(freq)
    tab = px.mag_words(tables)
    x0 = np.concatenate([rng.integers(0, 1 << 24, n - 4), [0, 1, L - 1, (1 << 24) - 1]]).astype(np.uint32)
    data = rng.integers(0, 256, 64).astype(np.uint8)
    p0 = rng.integers(0, data.size, n)                   # (up to the last byte: its pair reads a 0)
    ctx = rng.integers(0, C, n).astype(np.uint32)
    pair = np.concatenate([data, np.zeros(1, np.uint8)])
    pair = (pair[:-1].astype(np.uint32) << 8) | pair[1:]
    pair = np.concatenate([pair, np.zeros(2, np.uint32)])
    x, p, out = x0.copy(), p0.astype(np.intp), np.empty(n, np.uint32)
    c = ctx << np.uint32(PROB_BITS)
    px._step(tab, pair, c, x, p, np.empty(n, np.uint32), np.empty(n, np.uint32), out)
    slot_t, cum = tables.slot, tables.cum
    for i in range(n):
        xi, pi, ci = int(x0[i]), int(p0[i]), int(ctx[i])
        sl = xi & 4095
        s = int(slot_t[ci, sl])
        xi = int(freq[ci, s]) * (xi >> PROB_BITS) + sl - int(cum[ci, s])
        for _ in range(2):
            if xi < L:
                xi = (xi << 8) | (int(data[pi]) if pi < data.size else 0)
                pi += 1
        assert (int(out[i]), int(x[i]), int(p[i])) == (s, xi, pi), i


def test_the_plain_python_tail_of_a_zero_state_ends():
    """A damaged stream can bring a lane's rANS state to 0 (its stored state bytes zero). The
    numpy steps read at most two bytes per symbol; the plain-Python tail that finishes the last
    lanes read until the state reached RANS_L, and a 0 state fed with the clamped zero byte past
    the buffer never did (a decoder hung on such a file: found by the damaged-streams test).
    Now the tail reads at most two bytes per symbol too, the same as the numpy steps: the state
    stays 0 and the pointer moves two bytes a symbol (the caller's end check refuses the
    stream)."""
    from rlfc.txsyntax import CTX_MAG

    rng = np.random.default_rng(0)
    modes, levels = _random_blocks(rng, 2, 1, 1, 1.0, False)
    _, tables = _encode(modes, levels, np.zeros(2, np.int64), np.zeros(2, np.int64), tx.plane_classes(1))
    n = 3                                                                # symbols of the one lane
    c1 = np.full(n, CTX_MAG, np.uint32)
    x_all, p_all = np.zeros(1, np.uint32), np.zeros(1, np.int64)
    buf = np.zeros(4, np.uint8)
    args = (0, 1, list(range(n)), np.array([n]), c1, np.zeros(n, np.uint32), np.zeros(n, np.uint32),
            np.zeros(n, np.uint32), x_all, p_all, buf, buf.size - 1, tables)
    run = threading.Thread(target=px._ragged_tail, args=args, daemon=True)   # (a hang fails, not blocks)
    run.start()
    run.join(30)
    assert not run.is_alive(), "the tail never ended on a 0 state"
    assert int(x_all[0]) == 0 and int(p_all[0]) == 2 * n
