"""Key-view rows coded as several streams (``config.tx.key_split``, tx layout version 3): the
same pixels as one stream per row through every decoder path, an automatic choice that follows
the rows' bytes, typed errors for inconsistent headers, and the map streams' plain-Python parse
against the encoder."""
import copy
import dataclasses

import pytest

from formats.codec_api import EncodeOptions
from formats.container import build_container
from formats.errors import FormatError
from formats.lfcfile import encode_meta, open_lfc
from rlfc import RlfcDecoder, encode
from rlfc.torch_decode import TorchBlockDecoder
from tests.rlfc.helpers import check_agreement, open_encoded, smooth_lf


def tx(lf, **kw):
    # (versions 2 and 3: weighted prediction pinned off, so that these files stay what the tests
    # are about whatever its fits decide; test_weighted_prediction splits version 4 files' key rows)
    return encode(lf, EncodeOptions(profile="tx", params={"weighted": False, **kw}))


@pytest.fixture(scope="module")
def wide():
    """A 3×4 light field of 40×70 pixels: 8-pixel blocks, 9 per row (divisors 1, 3, 9)."""
    return smooth_lf(rows=3, cols=4, h=40, w=70)


@pytest.fixture(scope="module")
def one_per_row(wide):
    e = tx(wide, step=4.0, block_size=8, key_split=1)
    return e, open_encoded(wide, e)


@pytest.mark.parametrize("asked, got", [(3, 3), (5, 3), (9, 9)])
def test_split_rows_decode_to_the_same_pixels_on_every_path(wide, one_per_row, asked, got, rng):
    one, (d1, blob1) = one_per_row
    assert one.config["tx"]["version"] == 2 and "key_split" not in one.config["tx"]
    e = tx(wide, step=4.0, block_size=8, key_split=asked)
    assert e.config["tx"]["version"] == 3 and e.config["tx"]["key_split"] == got   # a divisor of 9, not above
    d, blob = open_encoded(wide, e)
    assert d.core.key_start.shape[-1] == got
    said = [x for x in e.notes if "--key-split" in x]       # a split that is not a divisor is reported
    assert said == ([] if asked == got else [f"--key-split {asked} does not divide the 9 blocks of a row: the key "
                                             f"rows are {got} streams each (the largest divisor below it)"])
    assert len(blob) > len(blob1)                       # each stream has its own state and length
    full = d.decode_all()
    assert (full == e.decoded).all() and (full == d1.decode_all()).all() and (e.decoded == one.decoded).all()
    check_agreement(d, wide.views.shape)
    n = wide.rows * wide.cols
    v, by, bx = rng.integers(0, n, 200), rng.integers(0, d.nby, 200), rng.integers(0, d.nbx, 200)
    assert (TorchBlockDecoder(d, "cpu").decode_blocks(v, by, bx) == d.decode_blocks(v, by, bx)).all()
    # a fresh decoder that parses one key row's streams, one by one (plain Python), the same
    fresh = RlfcDecoder(open_lfc(blob))
    import rlfc.profiles.tx_residual as T

    old = T.ONE_BY_ONE_RATIO
    try:
        T.ONE_BY_ONE_RATIO = 10 ** 9
        assert (fresh.decode_all() == full).all()
    finally:
        T.ONE_BY_ONE_RATIO = old


def test_auto_split_keeps_streams_of_at_least_the_segment_bytes(wide):
    """``key_split`` 0: the most streams per row (a divisor of the blocks per row) whose
    estimated bytes stay at least KEY_SEGMENT_BYTES; explicit values round down to a divisor."""
    import rlfc.txencode as T
    import rlfc.txpack as K
    import rlfc.txrate as R

    enc = T.TxEncoder(wide, R._params_from(EncodeOptions(params={"block_size": 8, "step": 4.0})), None, 10.0, None)
    res = enc.run(4.0, T.Model(T.default_counts()))
    ck = enc.coded_keys(res)
    assert ck and enc.nbx == 9

    def with_row_bytes(b):
        codes = list(res["codes"])
        for k in ck:
            codes[k] = dataclasses.replace(codes[k], bits=8.0 * b * enc.nby)
        return {**res, "codes": codes}

    seg = K.KEY_SEGMENT_BYTES
    assert enc.key_split(with_row_bytes(2.9 * seg)) == 1
    assert enc.key_split(with_row_bytes(3 * seg)) == 3
    assert enc.key_split(with_row_bytes(8.9 * seg)) == 3
    assert enc.key_split(with_row_bytes(9 * seg)) == 9
    enc.p = dataclasses.replace(enc.p, key_split=4)
    assert enc.key_split(with_row_bytes(0)) == 3



def test_auto_split_bounds_the_longest_stream_in_magnitude_symbols(wide, monkeypatch):
    """``key_split`` 0 splits rows that the bytes split further while the longest stream holds
    more than KEY_LANE_SYMBOLS magnitude symbols (the decoder's lockstep steps), never into
    streams under KEY_MIN_SEGMENT_BYTES; the per-block counts are the parser's lane lengths."""
    import numpy as np

    import rlfc.txencode as T
    import rlfc.txpack as K
    import rlfc.txrate as R
    import rlfc.txparse as ts

    enc = T.TxEncoder(wide, R._params_from(EncodeOptions(params={"block_size": 8, "step": 2.0})), None, 10.0, None)
    res = enc.run(2.0, T.Model(T.default_counts()))
    ck = enc.coded_keys(res)
    blocks = np.stack([enc._block_symbols(res["codes"][k]) for k in ck])          # (keys, nby, 9)
    longest = {d: int(blocks.reshape(len(ck), enc.nby, d, -1).sum(3).max()) for d in (1, 3, 9)}
    assert longest[1] > longest[3] > longest[9] > 0

    def with_row_bytes(b):
        codes = list(res["codes"])
        for k in ck:
            codes[k] = dataclasses.replace(codes[k], bits=8.0 * b * enc.nby)
        return {**res, "codes": codes}

    rows3 = with_row_bytes(3 * K.KEY_SEGMENT_BYTES)                     # the bytes alone: 3 streams
    monkeypatch.setattr(K, "KEY_LANE_SYMBOLS", longest[3])
    assert enc.key_split(rows3) == 3
    monkeypatch.setattr(K, "KEY_LANE_SYMBOLS", longest[3] - 1)
    assert enc.key_split(rows3) == 9
    monkeypatch.setattr(K, "KEY_MIN_SEGMENT_BYTES", K.KEY_SEGMENT_BYTES / 3 + 1)
    assert enc.key_split(rows3) == 3                                    # 9 streams would be too short
    monkeypatch.setattr(K, "KEY_LANE_SYMBOLS", 1)
    assert enc.key_split(with_row_bytes(2.9 * K.KEY_SEGMENT_BYTES)) == 1  # rows of one stream stay so

    # the counts are the lanes the decoder steps through (one stream per block: a lane per block)
    import rlfc.profiles.tx_residual as P

    monkeypatch.setattr(P, "ONE_BY_ONE_RATIO", 0)                      # (lanes, however few)
    seen = []
    orig = ts._magnitudes
    monkeypatch.setattr(ts, "_magnitudes", lambda dec, tables, S, per_lane, *a: seen.append(per_lane.copy())
                        or orig(dec, tables, S, per_lane, *a))
    enc.p = dataclasses.replace(enc.p, key_split=9)
    cfg, sections = enc.pack(res)
    d = RlfcDecoder(open_lfc(b"".join(bytes(p) for p in build_container(encode_meta("rlfc", 1, cfg, wide.geometry()),
                                                                         sections))))
    d.core.decode_keys()
    assert np.array_equal(np.sort(np.concatenate(seen)), np.sort(blocks.reshape(-1)))

def _with_tx(lf, e, **changes):
    cfg = copy.deepcopy(e.config)
    for k, v in changes.items():
        if v is None:
            cfg["tx"].pop(k, None)
        else:
            cfg["tx"][k] = v
    return b"".join(bytes(p) for p in build_container(encode_meta("rlfc", 1, cfg, lf.geometry()), e.sections))


@pytest.mark.parametrize("changes, words", [
    (dict(key_split=None), "key_split"),                       # version 3 without the split
    (dict(key_split=1), "key_split"),                          # a split of 1 is version 2's
    (dict(key_split=2), "does not divide"),
    (dict(key_split=9), "tx.index"),                           # the index holds 3 lengths per row
    (dict(version=2), "tx.index"),                             # read as one stream per row
    (dict(key_split=1 << 20), "key_split"),
])
def test_inconsistent_split_headers_are_typed_errors(wide, changes, words):
    e = tx(wide, step=4.0, block_size=8, key_split=3)
    blob = _with_tx(wide, e, **changes)
    with pytest.raises(FormatError, match=words):
        RlfcDecoder(open_lfc(blob)).decode_all()


def test_version_2_files_stay_byte_identical_without_a_split(wide, one_per_row):
    """A file whose key rows are one stream each is written exactly as before the split existed
    (version 2, no key_split field), so the auto choice changes nothing where rows are short."""
    e = tx(wide, step=4.0, block_size=8)                    # auto: rows of this size stay whole
    assert e.config["tx"]["version"] == 2 and "key_split" not in e.config["tx"]
    assert "key_split" not in e.config["params"]
    one, _ = one_per_row
    assert [s for _, s in e.sections] == [s for _, s in one.sections]


@pytest.mark.parametrize("kw", [dict(dtype="uint16"), dict(c=1), dict(c=2), dict(c=4), dict(h=13, w=37)])
def test_split_rows_on_every_sample_layout(kw):
    """Grey, grey + alpha, RGBA, 16-bit and a ragged width: split rows give the encoder's
    closed loop and the same pixels as one stream per row."""
    import numpy as np

    kw = dict(kw)
    if "dtype" in kw:
        kw["dtype"] = np.uint16
    lf = smooth_lf(rows=3, cols=3, **{"h": 24, "w": 40, **kw})
    step = 6.0 * (257 if kw.get("dtype") is np.uint16 else 1)
    whole = tx(lf, step=step, block_size=8, key_split=1)
    split = tx(lf, step=step, block_size=8, key_split=5)
    d, _ = open_encoded(lf, split)
    assert d.core.key_split == 5
    full = d.decode_all()
    assert (full == split.decoded).all() and (full == whole.decoded).all()
    if lf.channels in (2, 4):
        assert (full[..., -1] == lf.views[..., -1]).all()


@pytest.mark.parametrize("bad", [-1, 4097, True, 2.5, "4"])
def test_bad_key_split_is_a_parameter_error(bad):
    from formats.errors import ParameterError
    from rlfc.txparams import TxParams

    with pytest.raises(ParameterError, match="key.split"):
        TxParams(key_split=bad)
