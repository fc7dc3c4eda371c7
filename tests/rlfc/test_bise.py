"""BISE: conformance with ARM astc-encoder vectors, round-trip properties, bad input."""
import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from formats.errors import LfcError, ParameterError, TruncatedError
from rlfc import bise
from tests.conftest import ROOT, SHARED


def _cases():
    full = SHARED / "bise" / "bise_vectors_public.json"
    path = full if full.exists() else ROOT / "tests" / "data" / "bise_vectors_subset.json"
    return json.loads(path.read_text())["cases"]


CASES = _cases()


def test_vector_file_covers_all_ranges():
    assert {c["range"] for c in CASES} == set(bise.RANGE_VALUES)


@pytest.mark.parametrize("case", CASES, ids=[c["id"] for c in CASES])
def test_conformance(case):
    n, vals = case["range"], np.array(case["values"])
    assert bise.bit_length(case["count"], n) == case["bit_count"]
    assert bise.encode(vals, n).hex() == case["encoded_hex"]
    assert bise.decode(bytes.fromhex(case["encoded_hex"]), n, case["count"]).tolist() == case["values"]


def test_conformance_batched_grouped():
    """The batched, grouped path decodes every vector of one length at once, from one buffer."""
    for count in sorted({c["count"] for c in CASES}):
        sel = [c for c in CASES if c["count"] == count]
        vals = np.array([c["values"] for c in sel])
        ranges = np.array([c["range"] for c in sel])
        data, offs = bise.encode_grouped(vals, ranges)
        for c, a, b in zip(sel, offs[:-1], offs[1:]):
            assert data[a:b].tobytes().hex() == c["encoded_hex"]
        buf = np.concatenate([data, np.zeros(bise.SLACK, np.uint8)])
        assert (bise.decode_grouped(buf, offs[:-1], ranges, count) == vals).all()


def test_duplicate_codes_decode_and_encoder_picks_largest():
    from rlfc.bise_tables import TRIT_CODE, TRIT_DIGITS, QUINT_CODE, QUINT_DIGITS
    # (2,0,2,0,0) comes from codes 11 and 15; astc-encoder writes 15
    assert TRIT_DIGITS[11].tolist() == TRIT_DIGITS[15].tolist() == [2, 0, 2, 0, 0]
    assert TRIT_CODE[2 + 9 * 2] == 15
    assert QUINT_CODE[4 + 5 * 4 + 25 * 4] == 31
    for code in (7, 15, 23, 31):
        assert QUINT_DIGITS[code].tolist() == [4, 4, 4]
    # every code of either table decodes to digits whose re-encoding decodes the same
    assert (TRIT_DIGITS[TRIT_CODE[(TRIT_DIGITS * [1, 3, 9, 27, 81]).sum(1)]] == TRIT_DIGITS).all()
    assert (QUINT_DIGITS[QUINT_CODE[(QUINT_DIGITS * [1, 5, 25]).sum(1)]] == QUINT_DIGITS).all()


@settings(max_examples=150, deadline=None)
@given(n=st.sampled_from(bise.RANGE_VALUES), data=st.data())
def test_roundtrip_property(n, data):
    count = data.draw(st.integers(0, 4096))
    kind = data.draw(st.sampled_from(["random", "max", "zero"]))
    if kind == "random":
        seed = data.draw(st.integers(0, 2**32 - 1))
        vals = np.random.default_rng(seed).integers(0, n, count)
    else:
        vals = np.full(count, n - 1 if kind == "max" else 0)
    enc = bise.encode(vals, n)
    assert len(enc) == bise.byte_length(count, n)
    last_bits = bise.bit_length(count, n) % 8
    if enc and last_bits:
        assert enc[-1] >> last_bits == 0  # bits past the end are zero
    assert (bise.decode(enc, n, count) == vals).all()


@settings(max_examples=60, deadline=None)
@given(n=st.sampled_from(bise.RANGE_VALUES), nb=st.integers(0, 40), count=st.integers(0, 70),
       seed=st.integers(0, 2**32 - 1))
def test_batch_matches_single(n, nb, count, seed):
    vals = np.random.default_rng(seed).integers(0, n, (nb, count))
    enc = bise.encode_batch(vals, n)
    for i in range(nb):
        assert enc[i].tobytes() == bise.encode(vals[i], n)
    assert (bise.decode_batch(enc, n, count) == vals).all()


def test_smallest_range():
    assert bise.smallest_range(0) == 2
    assert bise.smallest_range(2) == 3
    assert bise.smallest_range(255) == 256
    assert bise.smallest_range(np.array([1, 4, 5, 100])).tolist() == [2, 5, 6, 128]
    with pytest.raises(ParameterError):
        bise.smallest_range(256)


@pytest.mark.parametrize("bad,exc", [
    (lambda: bise.encode([0, 8], 8), ParameterError),          # value out of range
    (lambda: bise.encode([0, -1], 8), ParameterError),         # negative
    (lambda: bise.encode([0.5, 1], 8), ParameterError),        # non-integer
    (lambda: bise.encode(np.array([1.0]), 8), ParameterError), # float dtype
    (lambda: bise.encode([0, 1], 7), ParameterError),          # not an ASTC range
    (lambda: bise.encode([0, 1], 512), ParameterError),
    (lambda: bise.decode(b"\x00", 12, 10), TruncatedError),    # buffer too short
    (lambda: bise.decode(b"", 2, 1), TruncatedError),
    (lambda: bise.decode(b"\x00", 2, -1), ParameterError),
    (lambda: bise.decode_batch(np.zeros((2, 1), np.uint8), 256, 2), TruncatedError),
    (lambda: bise.decode_at(np.zeros(5, np.uint8), [0], 256, 4), TruncatedError),
])
def test_bad_input_is_typed(bad, exc):
    with pytest.raises(exc) as ei:
        bad()
    assert isinstance(ei.value, LfcError) and str(ei.value)
