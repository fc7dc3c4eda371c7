"""rANS: round trips (property tests), lanes == scalar reference == torch, compression close to
the entropy, and malformed streams detected."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from formats.errors import FormatError
from rlfc.rans import M, LaneDecoder, ScalarDecoder, Tables, encode_lanes, normalize
from rlfc.xp import NUMPY, torch_backend


def _streams(rng, S, C, A, maxlen, skew=1.0):
    probs = rng.dirichlet(np.full(A, skew), size=C)
    lengths = rng.integers(0, maxlen + 1, S)
    K = max(1, int(lengths.max(initial=0)))
    ctx = rng.integers(0, C, (S, K))
    sym = np.stack([[rng.choice(A, p=probs[c]) for c in row] for row in ctx]) if S else np.zeros((0, K), int)
    counts = np.zeros((C, A))
    for i in range(S):
        np.add.at(counts, (ctx[i, :lengths[i]], sym[i, :lengths[i]]), 1)
    return ctx, sym, lengths, Tables.from_counts(counts + (counts.sum(1, keepdims=True) == 0))


def _decode_lanes(xp, blobs, ctx, lengths, tables):
    starts = np.concatenate([[0], np.cumsum([len(b) for b in blobs])]).astype(np.int64)
    buf = np.frombuffer(b"".join(blobs) + bytes(8), dtype=np.uint8)
    A = xp.asarray
    dec = LaneDecoder(xp, A(buf), A(starts[:-1]), tables)
    out = np.zeros(ctx.shape, dtype=np.int64)
    for k in range(ctx.shape[1]):
        lanes = np.flatnonzero(lengths > k)
        if lanes.size:
            s = dec.step(A(lanes), A(ctx[lanes, k]))
            out[lanes, k] = s if isinstance(s, np.ndarray) else s.cpu().numpy()
    ok = dec.check(A(starts[1:]))
    return out, (ok if isinstance(ok, np.ndarray) else ok.cpu().numpy())


@settings(max_examples=40)
@given(st.integers(0, 2 ** 32 - 1), st.integers(0, 30), st.integers(1, 5), st.integers(1, 40), st.integers(0, 60))
def test_round_trip_lanes_and_scalar(seed, S, C, A, maxlen):
    rng = np.random.default_rng(seed)
    ctx, sym, lengths, tables = _streams(rng, S, C, A, maxlen, skew=0.3)
    blobs = encode_lanes(ctx, sym, lengths, tables)
    out, ok = _decode_lanes(NUMPY, blobs, ctx, lengths, tables)
    for i in range(S):
        assert (out[i, :lengths[i]] == sym[i, :lengths[i]]).all()
        d = ScalarDecoder(blobs[i], tables)
        assert [d.get(int(c)) for c in ctx[i, :lengths[i]]] == sym[i, :lengths[i]].tolist()
        assert d.done(len(blobs[i]))
    assert ok.all()


def test_torch_lanes_equal_numpy():
    rng = np.random.default_rng(3)
    ctx, sym, lengths, tables = _streams(rng, 200, 4, 16, 80, skew=0.2)
    blobs = encode_lanes(ctx, sym, lengths, tables)
    a, oka = _decode_lanes(NUMPY, blobs, ctx, lengths, tables)
    b, okb = _decode_lanes(torch_backend("cpu"), blobs, ctx, lengths, tables)
    assert (a == b).all() and oka.all() and okb.all()


def test_size_close_to_entropy():
    rng = np.random.default_rng(5)
    p = np.array([0.7, 0.15, 0.08, 0.04, 0.02, 0.01])
    n = 20000
    sym = rng.choice(6, size=(1, n), p=p)
    tables = Tables.from_counts(np.bincount(sym[0], minlength=6)[None])
    blob = encode_lanes(np.zeros_like(sym), sym, np.array([n]), tables)[0]
    ideal = tables.bits(np.zeros(n, int), sym[0]).sum() / 8
    assert len(blob) <= ideal * 1.002 + 6, (len(blob), ideal)


def test_normalize_keeps_every_counted_symbol():
    f = normalize(np.array([10 ** 9, 1, 0, 3]))
    assert f.sum() == M and f[1] >= 1 and f[2] == 0 and f[3] >= 1
    assert normalize(np.zeros(5)).sum() == M


def test_malformed_streams_are_detected():
    rng = np.random.default_rng(7)
    ctx, sym, lengths, tables = _streams(rng, 50, 2, 8, 40)
    lengths[:] = np.maximum(lengths, 5)
    blobs = encode_lanes(ctx, sym, lengths, tables)
    bad = [b[:-1] if len(b) > 4 else b for b in blobs]          # truncated streams
    _, ok = _decode_lanes(NUMPY, bad, ctx, lengths, tables)
    assert not ok.all()
    with pytest.raises(FormatError):
        Tables.from_bytes(b"junk", 2, 8, "x")
    with pytest.raises(FormatError):
        ScalarDecoder(b"\x00\x01", tables)
    longest = int(np.argmax(lengths))                               # a stream cut to its state alone:
    d = ScalarDecoder(blobs[longest][:4], tables)                   # its decode reads past the end
    with pytest.raises(FormatError, match="reads past its end"):
        for c in ctx[longest, :lengths[longest]]:
            d.get(int(c))


@settings(max_examples=150, deadline=None, derandomize=True)
@given(st.integers(1, 6), st.integers(1, 200), st.integers(0, 3), st.integers(0, 2**32 - 1))
def test_tables_of_many_rows_are_each_rows_own(C, A, kind, seed):
    """``normalize_int_rows`` (every table of a file at once) gives each row exactly what
    ``normalize_int`` gives it alone: small counts, huge weights, few used symbols beside a
    dominant one, all-zero rows, and rows whose floors at 1 overshoot M."""
    from rlfc.rans import normalize_int, normalize_int_rows

    rng = np.random.default_rng(seed)
    if kind == 0:
        w = rng.integers(0, 50, (C, A))
        w[0] *= seed % 2                                   # (an all-zero row: a flat table)
    elif kind == 1:
        w = rng.integers(0, 1 << 40, (C, A)) * (rng.random((C, A)) < 0.3)
    elif kind == 2:
        w = (rng.random((C, A)) < 0.1) * rng.integers(1, 3, (C, A))
        w[:, 0] = rng.integers(0, 1 << 35, C)
    else:
        w = np.zeros((C, 4096), np.int64)                  # 4 095 symbols floored to 1: over M
        w[:, 1:] = rng.integers(0, 2, (C, 4095))
        w[:, 0] = 1 << 30
    got = normalize_int_rows(w)
    assert np.array_equal(got, np.stack([normalize_int(r) for r in w]))
    assert (got.sum(axis=1) == M).all()
