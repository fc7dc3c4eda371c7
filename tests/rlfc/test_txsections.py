"""The ``tx`` side sections' integer packing (:mod:`rlfc.txsections`): zig-zag LEB128 varints,
the thumbnails and the index, round trips over their whole ranges (hypothesis) and every
malformed form refused with a FormatError."""
import zlib

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from formats.errors import FormatError
from rlfc.txsections import (MAX_VARINT_BYTES, pack_index, pack_thumbs, unpack_index, unpack_thumbs, unvarints,
                             varints)

INT64 = hnp.arrays(np.int64, st.integers(0, 300), elements=st.integers(-2 ** 63, 2 ** 63 - 1))


@given(INT64)
def test_varints_round_trip_every_int64(v):
    data = varints(v)
    assert (unvarints(data, v.size, "t") == v).all()
    b = np.frombuffer(data, np.uint8)
    assert int((b < 128).sum()) == v.size                      # one final byte per value
    # zig-zag: small magnitudes take one byte whatever their sign
    assert len(varints(np.clip(v, -64, 63))) == v.size


@given(INT64.filter(lambda v: v.size > 0), st.data())
def test_damaged_varints_are_refused(v, data):
    raw = bytearray(varints(v))
    with pytest.raises(FormatError):
        unvarints(bytes(raw), v.size + 1, "t")                 # too few values
    with pytest.raises(FormatError):
        unvarints(bytes(raw[:-1]) + bytes([raw[-1] | 128]), v.size, "t")   # the last one never ends
    with pytest.raises(FormatError):
        unvarints(bytes(raw) + b"\x01", v.size, "t")          # trailing bytes
    i = data.draw(st.integers(0, v.size - 1))
    long = varints(v[:i]) + bytes([0x80] * MAX_VARINT_BYTES) + b"\x00" + varints(v[i + 1:])
    with pytest.raises(FormatError, match="longer"):
        unvarints(long, v.size, "t")                           # a value of 11 bytes


def test_no_varints_and_empty_data():
    assert unvarints(b"", 0, "t").size == 0 and varints(np.zeros(0, np.int64)) == b""
    with pytest.raises(FormatError):
        unvarints(b"\x00", 0, "t")


@given(hnp.arrays(np.int64, st.tuples(st.integers(1, 4), st.integers(1, 5), st.integers(1, 6), st.integers(1, 4)),
                  elements=st.integers(-(1 << 24), 1 << 24)))
def test_thumbnails_round_trip(levels):
    assert np.array_equal(unpack_thumbs(pack_thumbs(levels), levels.shape, "t"), levels)


def test_damaged_thumbnails_are_refused():
    levels = np.arange(2 * 3 * 4 * 3, dtype=np.int64).reshape(2, 3, 4, 3)
    data = pack_thumbs(levels)
    with pytest.raises(FormatError):
        unpack_thumbs(data[:-3], levels.shape, "t")            # a truncated zlib stream
    with pytest.raises(FormatError):
        unpack_thumbs(data, (2, 3, 4, 4), "t")                 # fewer levels than the shape asks
    big = levels.copy()
    big[1, 2, 3, 0] = (1 << 24) + 1
    with pytest.raises(FormatError, match="out of range"):
        unpack_thumbs(pack_thumbs(big), big.shape, "t")
    with pytest.raises(FormatError):                          # a stream inflating past its bound
        unpack_thumbs(zlib.compress(bytes(10 ** 4)), levels.shape, "t")


@given(st.integers(1, 3), st.integers(1, 4), st.integers(2, 5), st.integers(1, 9), st.data())
def test_index_round_trip(n_keys, nby, n_views, nloc, data):
    is_key = np.zeros(n_views, bool)
    is_key[:min(n_keys, n_views - 1)] = True
    coded = np.array(data.draw(st.lists(st.booleans(), min_size=n_views * nloc, max_size=n_views * nloc)),
                      bool).reshape(n_views, nloc) & ~is_key[:, None]
    key_lengths = np.array(data.draw(st.lists(st.integers(3, 1 << 28), min_size=n_keys * nby,
                                              max_size=n_keys * nby)), np.int64).reshape(n_keys, nby)
    lengths = np.array(data.draw(st.lists(st.integers(3, 1 << 28), min_size=int(coded.sum()),
                                          max_size=int(coded.sum()))), np.int64)
    k2, c2, l2 = unpack_index(pack_index(key_lengths, coded, lengths), n_keys, nby, n_views, nloc, is_key, "t")
    assert np.array_equal(k2, key_lengths) and np.array_equal(c2, coded) and np.array_equal(l2, lengths)


def test_damaged_index_is_refused():
    is_key = np.array([True, False, False])
    coded = np.array([[False, False], [True, False], [True, True]])
    good = pack_index(np.array([[5, 6]]), coded, np.array([7, 8, 9]))
    assert unpack_index(good, 1, 2, 3, 2, is_key, "t")[1].sum() == 3
    cases = [pack_index(np.array([[5, 2]]), coded, np.array([7, 8, 9])),          # a stream below its 3-byte state
             pack_index(np.array([[5, 6]]), coded, np.array([7, 8, (1 << 28) + 1])),
             pack_index(np.array([[5, 6]]), np.array([[True, False], [True, False], [True, True]]),
                        np.array([7, 7, 8, 9])),                                  # a key view's block marked
             pack_index(np.array([[5, 6]]), coded, np.array([7, 8])),             # a length missing
             good[:-2]]
    for data in cases:
        with pytest.raises(FormatError):
            unpack_index(data, 1, 2, 3, 2, is_key, "t")
