"""tx.maps: the shared map, per-map corrections and modes round-trip through pack_maps /
unpack_maps in the current layout (version 3: one context per escape digit position) and in
the previous one (version 2, files written before it), escapes of every size included;
malformed sections raise FormatError."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from formats.errors import FormatError
from rlfc import txmaps


def _maps(rng, n_maps, ny, nx, spread, big):
    """Disparity maps (1/16 px) near a smooth base, some blocks far off (escapes: corrections
    of 31 or more), and modes 0..4."""
    nloc = ny * nx
    base = np.cumsum(rng.integers(-3, 4, nloc)).astype(np.int64)
    corr = np.where(rng.random((n_maps, nloc)) < 0.3, rng.integers(-spread, spread + 1, (n_maps, nloc)), 0)
    far = rng.random((n_maps, nloc)) < big
    corr[far] = rng.integers(-(1 << 17), 1 << 17, int(far.sum()))        # all three escape digits in use
    modes = np.where(rng.random((n_maps, nloc)) < 0.1, rng.integers(0, 5, (n_maps, nloc)), 0)
    return base, base[None, :] + corr, modes


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2 ** 32 - 1), n_maps=st.integers(0, 4), ny=st.integers(1, 9), nx=st.integers(1, 9),
       version=st.sampled_from([2, 3]), big=st.sampled_from([0.0, 0.05, 0.5]), flat=st.booleans())
def test_maps_round_trip(seed, n_maps, ny, nx, version, big, flat):
    """``flat``: a base map of constant runs and mostly zero corrections and modes (the parsers'
    shortcut for the common symbol where the neighbours agree), else a random walk."""
    rng = np.random.default_rng(seed)
    base, disp, modes = _maps(rng, n_maps, ny, nx, 80, big)
    if flat:
        base = np.repeat(rng.integers(-40, 40, ny * nx), rng.integers(1, 12, ny * nx))[:ny * nx].astype(np.int64)
        keep = rng.random(disp.shape) < 0.03
        disp = base[None, :] + np.where(keep, rng.integers(-80, 81, disp.shape), 0)
        modes = np.where(rng.random(modes.shape) < 0.03, modes, 0)
    data = txmaps.pack_maps(base, disp, modes, (ny, nx), version=version)
    assert data[0] == version
    d2, m2 = txmaps.unpack_maps(data, n_maps, (ny, nx), 5, "t")
    if n_maps:
        assert np.array_equal(d2, disp) and np.array_equal(m2, modes)


def test_escape_digits_in_their_own_contexts_cost_less():
    """Maps with many large corrections (a wide-baseline grid's cells disagree by more than two
    pixels per view step): version 3 codes the escape digits per position, smaller than
    version 2's one shared table, and the encoder writes version 3."""
    rng = np.random.default_rng(5)
    base, disp, modes = _maps(rng, 24, 40, 40, 40, 0.0)
    corr = disp - base[None, :]
    far = rng.random(corr.shape) < 0.08
    corr[far] = np.sign(rng.standard_normal(int(far.sum()))).astype(np.int64) * (31 + rng.geometric(0.02, int(far.sum())))
    disp = base[None, :] + corr
    v2 = txmaps.pack_maps(base, disp, modes, (40, 40), version=2)
    v3 = txmaps.pack_maps(base, disp, modes, (40, 40))
    assert v3[0] == txmaps.VERSION == 3
    assert len(v3) < 0.97 * len(v2)
    for data in (v2, v3):
        d2, m2 = txmaps.unpack_maps(data, 24, (40, 40), 5, "t")
        assert np.array_equal(d2, disp) and np.array_equal(m2, modes)


def test_bad_maps_sections_are_refused():
    rng = np.random.default_rng(1)
    base, disp, modes = _maps(rng, 2, 4, 4, 80, 0.2)
    good = txmaps.pack_maps(base, disp, modes, (4, 4))
    for bad in (b"", bytes([4]) + good[1:], bytes([0]) + good[1:], good[:len(good) // 2]):
        with pytest.raises(FormatError):
            txmaps.unpack_maps(bad, 2, (4, 4), 5, "t")
    with pytest.raises(ValueError):
        txmaps.pack_maps(base, disp, modes, (4, 4), version=1)


def test_every_byte_flip_of_a_maps_section_is_refused_or_in_range():
    """The per-map streams are parsed in plain Python from the section's bytes: a flipped byte
    anywhere (lengths, tables, streams; the last stream running off the section's end) is a
    FormatError or a decode within the documented ranges, never another exception."""
    rng = np.random.default_rng(3)
    base, disp, modes = _maps(rng, 3, 5, 6, 80, 0.1)
    good = txmaps.pack_maps(base, disp, modes, (5, 6))
    refused = 0
    for i in range(1, len(good)):
        for bit in (0, 7):
            bad = bytearray(good)
            bad[i] ^= 1 << bit
            try:
                d2, m2 = txmaps.unpack_maps(bytes(bad), 3, (5, 6), 5, "t")
            except FormatError:
                refused += 1
                continue
            assert d2.shape == m2.shape == (3, 30) and m2.min() >= 0 and m2.max() <= 4
            assert np.abs(d2).max() <= 1 << 20
    assert refused > len(good)                          # most flips are caught


@pytest.mark.parametrize("seed, big", [(7, 0.1), (8, 0.4), (9, 0.0)])
def test_estimated_sizes_are_the_coded_ones_within_a_few_bytes(seed, big):
    """maps_bytes estimates each variant's section without coding it: every size within 1% + 8
    bytes of the coded section, and what one map costs (the section with it less the section
    without it: what the encoder asks) within 1% + 4 bytes."""
    rng = np.random.default_rng(seed)
    base, disp, modes = _maps(rng, 6, 12, 16, 80, big)
    variants = [(disp, modes)]
    for c in range(4):
        d2, m2 = disp.copy(), modes.copy()
        d2[c], m2[c] = base, 0
        variants.append((d2, m2))
    est = np.array(txmaps.maps_bytes(base, variants, (12, 16)))
    coded = np.array([len(txmaps.pack_maps(base, d, m, (12, 16))) for d, m in variants])
    assert (np.abs(est - coded) <= 0.01 * coded + 8).all(), (est, coded)
    cost, cost_coded = est[0] - est[1:], coded[0] - coded[1:]
    assert (cost_coded > 0).all()
    assert (np.abs(cost - cost_coded) <= 0.01 * cost_coded + 4).all(), (cost, cost_coded)
    assert txmaps.maps_bytes(base, [], (12, 16)) == []


def test_lazy_maps_decode_each_map_when_asked_and_check_it_then():
    """LazyMaps decodes the shared map with the first map asked for and each map's stream on its
    first request (the same values as decoding all); a damaged map is refused when it is asked
    for, the others still decode; a damaged shared map opens and is refused with the first map;
    and a map whose modes exceed its views' references is refused."""
    rng = np.random.default_rng(11)
    base, disp, modes = _maps(rng, 4, 6, 5, 80, 0.1)
    data = txmaps.pack_maps(base, disp, modes, (6, 5))
    lm = txmaps.LazyMaps(data, 4, (6, 5), 5, "t")
    assert not lm.done.any() and np.array_equal(lm.base, base)
    assert lm.need([2, 2]) == [2] and lm.need([2]) == [] and lm.done.tolist() == [False, False, True, False]
    assert np.array_equal(lm.disp[2], disp[2]) and np.array_equal(lm.modes[2], modes[2])
    assert not lm.disp[[0, 1, 3]].any()
    d2, m2 = lm.all()
    assert np.array_equal(d2, disp) and np.array_equal(m2, modes)
    # the third map's stream damaged: open and the other maps still work, the third is refused
    bad = bytearray(data)
    lm = txmaps.LazyMaps(data, 4, (6, 5), 5, "t")
    a, b = int(lm.starts[2]), int(lm.starts[3])
    bad[a:b] = bytes(b - a)
    lm = txmaps.LazyMaps(bytes(bad), 4, (6, 5), 5, "t")
    lm.need([0, 1, 3])
    assert np.array_equal(lm.disp[[0, 1, 3]], disp[[0, 1, 3]])
    with pytest.raises(FormatError):
        lm.need([2])
    assert not lm.done[2]
    # the shared map's stream damaged (it lies before the first map's): open reads lengths and
    # tables only; the first map asked for decodes it and refuses the file
    lm = txmaps.LazyMaps(data, 4, (6, 5), 5, "t")
    a = int(lm._base_span[0])
    bad = bytearray(data)
    bad[a:int(lm.starts[0])] = bytes(int(lm.starts[0]) - a)
    lm = txmaps.LazyMaps(bytes(bad), 4, (6, 5), 5, "t")
    with pytest.raises(FormatError):
        lm.need([0])
    limit = np.array([4, 4, 4, int(modes[3].max()) - 1])
    lm = txmaps.LazyMaps(data, 4, (6, 5), 5, "t", limit)
    lm.need([0, 1, 2])
    with pytest.raises(FormatError, match="reference"):
        lm.need([3])
