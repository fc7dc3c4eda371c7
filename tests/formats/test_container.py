"""The .lfc container: round trips, partial reads, corruption, truncation, hostile headers."""
import struct

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from formats.container import (HEADER_SIZE, MAGIC, ByteRangeSource, Container, build_container, crc32,
                               write_container)
from formats.errors import ChecksumError, FormatError, LfcError, TruncatedError, UnsupportedError
from formats.lfcfile import open_lfc, write_lfc


def _bytes(meta=b'{"format":"lfc","codec":"x"}', sections=(("a", b"A" * 1000), ("b", b"")), chunk=64):
    return b"".join(bytes(p) for p in build_container(meta, sections, chunk))


names = st.text(alphabet="abcdefghijklmnopqrstuvwxyz.", min_size=1, max_size=16).filter(lambda s: s != "meta")


@settings(max_examples=60, deadline=None)
@given(secs=st.lists(st.tuples(names, st.binary(max_size=3000)), max_size=6, unique_by=lambda t: t[0]),
       chunk=st.sampled_from([1, 7, 64, 4096]), data=st.data())
def test_roundtrip_property(secs, chunk, data):
    blob = _bytes(b"{}", secs, chunk)
    c = Container(blob)
    assert list(c.sections) == ["meta"] + [n for n, _ in secs]
    for n, d in secs:
        assert bytes(c.read(n)) == d
        if d:
            a = data.draw(st.integers(0, len(d)))
            b = data.draw(st.integers(a, len(d)))
            assert bytes(c.read(n, a, b)) == d[a:b]
    c.verify_all()
    assert c.size == len(blob)


def test_sections_tile_the_file():
    blob = _bytes()
    c = Container(blob)
    infos = list(c.sections.values())
    for x, y in zip(infos, infos[1:]):
        assert x.offset + x.length == y.offset
    assert infos[-1].offset + infos[-1].length == len(blob)


def test_write_is_atomic_and_roundtrips(tmp_path):
    p = tmp_path / "x.lfc"
    p.write_bytes(b"old contents")
    n = write_lfc(p, "x", 1, {"k": 1}, {"rows": 1}, [("data", b"123")])
    assert p.stat().st_size == n
    assert [q.name for q in tmp_path.iterdir()] == ["x.lfc"]
    with open_lfc(p) as f:
        assert f.meta["config"] == {"k": 1}
        assert bytes(f.container.read("data")) == b"123"


def test_failed_write_keeps_the_old_file(tmp_path):
    p = tmp_path / "x.lfc"
    p.write_bytes(b"old")
    with pytest.raises(FormatError):
        write_container(p, b"{}", [("a", b"1"), ("a", b"2")])   # duplicate names
    assert p.read_bytes() == b"old"
    assert [q.name for q in tmp_path.iterdir()] == ["x.lfc"]


def test_unknown_sections_are_skipped():
    blob = _bytes(sections=(("future.thing", b"?" * 10), ("a", b"A")))
    c = Container(blob)
    assert bytes(c.read("a")) == b"A"


def test_byte_range_source_fetches_only_what_is_read():
    blob = _bytes(sections=(("big", bytes(range(256)) * 4096),), chunk=4096)
    src = ByteRangeSource(lambda a, b: blob[a:b], len(blob))
    c = Container(src)
    opened = src.bytes_fetched
    assert opened == HEADER_SIZE + 48 * 2 + 4 * (1 + 256)   # header + table + chunk CRCs only
    assert bytes(c.read("big", 5000, 5010)) == (bytes(range(256)) * 4096)[5000:5010]
    assert src.bytes_fetched - opened == 4096              # exactly the one checksum chunk
    c.read("big", 5001, 5002)
    assert src.bytes_fetched - opened == 4096 + 1          # verified chunks are not re-verified


@pytest.mark.parametrize("name", ["meta", "a", "z"])
def test_flipped_byte_in_each_section_is_named(name):
    blob = bytearray(_bytes(sections=(("a", b"A" * 1000), ("z", b"Z" * 10))))
    c = Container(bytes(blob))
    info = c.info(name)
    blob[info.offset + info.length // 2] ^= 0x10
    c = Container(bytes(blob))
    with pytest.raises(ChecksumError, match=repr(name)):
        c.read(name)
    with pytest.raises(ChecksumError):
        c.verify_all()


def test_flipped_byte_in_table_is_detected():
    blob = bytearray(_bytes())
    blob[HEADER_SIZE + 20] ^= 1
    with pytest.raises(ChecksumError, match="header"):
        Container(bytes(blob))


def test_wrong_magic():
    blob = bytearray(_bytes())
    blob[1] = ord("X")
    with pytest.raises(FormatError, match="magic"):
        Container(bytes(blob))
    with pytest.raises(FormatError, match="magic"):
        Container(b"GIF89a" + bytes(100))


def test_newer_major_version():
    blob = bytearray(_bytes())
    blob[8:10] = struct.pack("<H", 2)
    with pytest.raises(UnsupportedError, match="newer"):
        Container(bytes(blob))


def test_newer_minor_version_is_read():
    head = struct.pack("<8sHHII", MAGIC, 1, 7, 1, 1)
    meta = b"{}"
    table = struct.pack("<16sQQIII4x", b"meta", HEADER_SIZE + 48 + 4, len(meta), 64, 0, 0) + struct.pack("<I", crc32(meta))
    blob = head + struct.pack("<I", crc32(head + table)) + bytes(8) + table + meta
    c = Container(blob)
    assert c.version == (1, 7) and bytes(c.read("meta")) == b"{}"


@pytest.mark.parametrize("cut", [0, 5, HEADER_SIZE - 1, HEADER_SIZE + 10, -1, -500])
def test_truncated(cut):
    blob = _bytes()
    with pytest.raises((TruncatedError, FormatError)) as ei:
        Container(blob[:cut] if cut else b"")
    assert "truncated" in str(ei.value) or "magic" in str(ei.value) or "bytes" in str(ei.value)


def test_truncated_file_names_the_section(tmp_path):
    p = tmp_path / "t.lfc"
    p.write_bytes(_bytes()[:-300])
    with pytest.raises(TruncatedError, match="'a'"):
        Container(p)


def test_huge_declared_lengths_do_not_allocate():
    blob = bytearray(_bytes())
    blob[12:16] = struct.pack("<I", 4000)          # n_sections, table would pass the end of file
    with pytest.raises(TruncatedError):
        Container(bytes(blob))
    blob = bytearray(_bytes())
    blob[16:20] = struct.pack("<I", 2**32 - 1)       # n_crcs: 16 GiB of CRCs
    with pytest.raises(TruncatedError):
        Container(bytes(blob))
    blob = bytearray(_bytes())
    blob[12:16] = struct.pack("<I", 2**31)
    with pytest.raises(FormatError):
        Container(bytes(blob))


def test_huge_section_length_is_rejected():
    """A section length of 2^60 with a matching header CRC: inconsistent, not allocated."""
    blob = bytearray(_bytes())
    c = Container(bytes(blob))
    n_sec = len(c.sections)
    ent = HEADER_SIZE + 48 * 1
    blob[ent + 24:ent + 32] = struct.pack("<Q", 2**60)
    table_end = HEADER_SIZE + 48 * n_sec + 4 * int.from_bytes(blob[16:20], "little")
    blob[20:24] = struct.pack("<I", crc32(bytes(blob[:20]) + bytes(blob[HEADER_SIZE:table_end])))
    with pytest.raises(FormatError):
        Container(bytes(blob))


def test_trailing_garbage_and_missing_file(tmp_path):
    with pytest.raises(FormatError, match="unexpected bytes"):
        Container(_bytes() + b"junk")
    with pytest.raises(FormatError, match="cannot open"):
        Container(tmp_path / "nope.lfc")


def test_errors_are_lfc_errors():
    for e in (ChecksumError, FormatError, TruncatedError, UnsupportedError):
        assert issubclass(e, LfcError)


def test_metadata_must_be_lfc_json():
    blob = _bytes(meta=b"not json")
    with pytest.raises(FormatError, match="JSON"):
        open_lfc(blob)
    with pytest.raises(FormatError, match="metadata"):
        open_lfc(_bytes(meta=b'{"a": 1}'))


def test_verify_ranges_checks_each_touched_chunk():
    payload = bytes(np.random.default_rng(0).integers(0, 256, 10000, dtype=np.uint8))
    blob = bytearray(_bytes(sections=(("p", payload),), chunk=100))
    c = Container(bytes(blob))
    c.verify_ranges("p", np.array([0, 950]), np.array([10, 1210]))
    info = c.info("p")
    blob[info.offset + 1150] ^= 1
    c = Container(bytes(blob))
    c.verify_ranges("p", np.array([0]), np.array([1000]))
    with pytest.raises(ChecksumError, match="chunk 11"):
        c.verify_ranges("p", np.array([950]), np.array([1210]))
