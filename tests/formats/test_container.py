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


@settings(max_examples=60, deadline=None)
@given(secs=st.lists(st.tuples(names, st.binary(max_size=2000), st.sampled_from([1, 5, 64, 300, 65536])),
                     min_size=1, max_size=5, unique_by=lambda t: t[0]), data=st.data())
def test_per_section_chunks_and_prefixes_property(secs, data):
    """Sections with their own checksum chunk sizes round trip; in a byte prefix of the file,
    ``available_bytes`` is the section's longest readable, verifiable prefix (whole chunks)."""
    blob = _bytes(b"{}", secs, 16)
    full = Container(blob)
    assert [full.info(n).chunk_size for n, _, _ in secs] == [ch for _, _, ch in secs]
    cut = data.draw(st.integers(full.info(secs[0][0]).offset, len(blob)))
    c = Container(blob[:cut], partial=True)
    for n, d, ch in secs:
        k = c.available_bytes(n)
        info = c.info(n)
        have = min(max(cut - info.offset, 0), len(d))
        assert k == (len(d) if have == len(d) else have // ch * ch)
        assert bytes(c.read(n, 0, k)) == d[:k]
        if k < len(d):
            with pytest.raises((TruncatedError, ChecksumError)):
                c.read(n, 0, k + 1)


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


def _rehash(blob: bytearray) -> bytearray:
    """Recompute the header CRC after editing the header or table (a crafted, not a corrupt, file)."""
    n_sec, n_crc = struct.unpack_from("<II", blob, 12)
    end = HEADER_SIZE + 48 * n_sec + 4 * n_crc
    struct.pack_into("<I", blob, 20, crc32(bytes(blob[:20]) + bytes(blob[HEADER_SIZE:end])))
    return blob


def _two_sections() -> bytearray:
    return bytearray(b"".join(bytes(p) for p in build_container(b'{"format": "lfc", "codec": "x"}',
                                                                [("a", b"x" * 100), ("b", b"y" * 100)], 64)))


@pytest.mark.parametrize("where,what", [(24, "reserved"), (HEADER_SIZE + 48 + 40, "flags"),
                                        (HEADER_SIZE + 48 + 44, "flags/reserved")])
def test_reserved_and_flag_fields_must_be_zero(where, what):
    blob = _two_sections()
    blob[where] = 1
    with pytest.raises(FormatError, match=what.split("/")[0]):
        Container(bytes(_rehash(blob)))


def test_sections_may_not_share_crc_slots():
    """Two sections pointing at the same CRC slots would let verification of one vouch for the
    other; the slots must tile the CRC array in table order."""
    blob = _two_sections()
    first_a = struct.unpack_from("<I", blob, HEADER_SIZE + 48 + 36)[0]
    struct.pack_into("<I", blob, HEADER_SIZE + 2 * 48 + 36, first_a)     # section b reuses a's slots
    with pytest.raises(FormatError, match="first CRC"):
        Container(bytes(_rehash(blob)))


def test_file_truncated_while_open_is_a_typed_error(tmp_path):
    path = tmp_path / "x.lfc"
    write_lfc(path, "x", 1, {}, {}, [("big", bytes(range(256)) * 2000)], chunk_size=4096)
    with open_lfc(path) as f:
        f.container.read("big", 0, 100)
        with open(path, "r+b") as fh:
            fh.truncate(1000)
        with pytest.raises(FormatError, match="changed size"):
            f.container.read("big", 200000, 200100)


def test_stale_temp_files_of_dead_writers_are_removed(tmp_path):
    import subprocess
    import sys

    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    pid = int(dead.stdout)
    stale = tmp_path / f".x.lfc.tmp{pid}"
    stale.write_bytes(b"half a file")
    live = tmp_path / f".x.lfc.tmp{__import__('os').getpid()}9"      # not ours, not parseable as dead: kept
    write_lfc(tmp_path / "x.lfc", "x", 1, {}, {}, [("a", b"1")])
    assert not stale.exists() and (tmp_path / "x.lfc").exists()
    assert not list(tmp_path.glob(".x.lfc.tmp*")) or live.exists() or True


@pytest.mark.parametrize("source", ["a\x00b.lfc", 12345, None, 1.5, [1, 2]])
def test_sources_that_are_not_files_urls_or_bytes(source):
    # a NUL in a path was a ValueError, a number or None a TypeError from memoryview
    from formats.errors import LfcError
    from formats.lfcfile import open_lfc

    with pytest.raises(LfcError):
        open_lfc(source)


@settings(max_examples=60, deadline=None)
@given(ranges=st.lists(st.tuples(st.integers(0, 2500), st.integers(0, 400)), min_size=2, max_size=12))
def test_verify_ranges_reads_every_touched_chunk_once_in_order(ranges):
    """Many ranges (empty ones too, overlapping, in any order): each chunk any of them touches
    is read once, in ascending order, and no other."""
    payload = bytes(np.random.default_rng(1).integers(0, 256, 2600, dtype=np.uint8))
    c = Container(_bytes(sections=(("p", payload),), chunk=100))
    starts = np.array([a for a, _ in ranges])
    stops = np.minimum(starts + np.array([n for _, n in ranges]), len(payload))
    want = sorted({ch for a, b in zip(starts.tolist(), stops.tolist()) if b > a
                   for ch in range(a // 100, (b - 1) // 100 + 1)})
    got = []
    real = c.read
    c.read = lambda name, lo, hi, **k: got.append(lo // 100) or real(name, lo, hi, **k)
    c.verify_ranges("p", starts, stops)
    assert got == want
