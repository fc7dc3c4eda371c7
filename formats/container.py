"""The ``.lfc`` container: magic + version, a checksummed section table, named sections.

Layout (all integers little-endian; see docs/FORMAT.md for the full specification)::

    0   8  magic  89 4C 46 43 0D 0A 1A 0A
    8   2  major version (u16)   10  2  minor version (u16)
    12  4  n_sections (u32)      16  4  n_crcs (u32)
    20  4  header CRC-32 over bytes [0, 20) + section table + CRC array
    24  8  reserved, zero
    32     section table: n_sections entries of 48 bytes
           name[16] (ASCII, NUL-padded) | offset u64 | length u64 | chunk_size u32 |
           first_crc u32 | flags u32 | reserved u32
           CRC array: n_crcs × u32, CRC-32 (zlib) of each chunk of each section
           section data, in table order, contiguous, ending exactly at the end of the file

Each section is checksummed in chunks of ``chunk_size`` bytes so that a random-access read
verifies exactly the chunks it fetched. Readers skip sections whose names they do not know.
The container never imports a codec.
"""
from __future__ import annotations

import mmap
import os
import stat
import struct
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterable

import numpy as np

from .errors import ChecksumError, FormatError, ParameterError, TruncatedError, UnsupportedError

MAGIC = b"\x89LFC\r\n\x1a\n"
MAJOR, MINOR = 1, 0
HEADER_SIZE = 32
ENTRY_SIZE = 48
MAX_SECTIONS = 4096
DEFAULT_CHUNK = 1 << 16
_HDR = struct.Struct("<8sHHIII8s")
_ENTRY = struct.Struct("<16sQQIII4s")


@dataclass(frozen=True)
class SectionInfo:
    """One entry of the section table (offsets and lengths in bytes)."""

    name: str
    offset: int
    length: int
    chunk_size: int
    first_crc: int
    flags: int = 0

    @property
    def n_chunks(self) -> int:
        return -(-self.length // self.chunk_size) if self.length else 0


def crc32(data) -> int:
    """CRC-32 (ISO-HDLC, as zlib.crc32) of a bytes-like object."""
    return zlib.crc32(data) & 0xFFFFFFFF


class ByteRangeSource:
    """A byte source given by a fetch function, e.g. HTTP range requests.

    Args:
        fetch: ``fetch(start, stop) -> bytes`` returning bytes [start, stop) of the file.
        size: total size of the file in bytes.
    """

    def __init__(self, fetch: Callable[[int, int], bytes], size: int):
        self._fetch = fetch
        self.size = int(size)
        self.bytes_fetched = 0
        self.requests = 0

    def read(self, start: int, stop: int) -> bytes:
        data = self._fetch(start, stop)
        self.bytes_fetched += len(data)
        self.requests += 1
        if len(data) != stop - start:
            raise TruncatedError(f"byte source returned {len(data)} bytes for range [{start}, {stop})")
        return data


class _BufferSource:
    def __init__(self, buf):
        self._buf = memoryview(buf).cast("B") if not isinstance(buf, memoryview) else buf.cast("B")
        self.size = len(self._buf)
        self.bytes_fetched = 0
        self.requests = 0

    def read(self, start: int, stop: int):
        self.bytes_fetched += stop - start
        self.requests += 1
        return self._buf[start:stop]


def build_container(meta_json: bytes, sections: Iterable[tuple], chunk_size: int = DEFAULT_CHUNK) -> list:
    """Assemble a container; returns the list of byte pieces to write in order.

    Args:
        meta_json: UTF-8 JSON of the file's metadata; stored as the first section, "meta".
        sections: (name, data) or (name, data, chunk_size) tuples in the order they should
            appear (put what a progressive reader needs first at the front); a third item sets
            that section's checksum granularity (e.g. small chunks where a reader takes
            prefixes of a section).
        chunk_size: checksum granularity in bytes of the other sections.
    """
    items = [("meta", bytes(meta_json), chunk_size)] + [(s[0], s[1], s[2] if len(s) > 2 else chunk_size)
                                                        for s in sections]
    names = [n for n, _, _ in items]
    if len(set(names)) != len(names):
        raise FormatError(f"duplicate section names: {names}")
    if len(items) > MAX_SECTIONS:
        raise FormatError(f"too many sections ({len(items)} > {MAX_SECTIONS})")
    for n, _, ch in items:
        if not n or len(n.encode("ascii")) > 16:
            raise FormatError(f"section name {n!r} must be 1-16 ASCII characters")
        if not 0 < ch < 2 ** 32:
            raise FormatError(f"section {n!r}: chunk size {ch} outside 1..2^32-1")
    crcs: list[int] = []
    entries = []
    views = [memoryview(d).cast("B") for _, d, _ in items]
    n_crcs = sum(-(-len(v) // ch) for v, (_, _, ch) in zip(views, items))
    offset = HEADER_SIZE + ENTRY_SIZE * len(items) + 4 * n_crcs
    for (name, _, ch), v in zip(items, views):
        first = len(crcs)
        crcs.extend(crc32(v[i:i + ch]) for i in range(0, len(v), ch))
        entries.append(_ENTRY.pack(name.encode("ascii"), offset, len(v), ch, first, 0, bytes(4)))
        offset += len(v)
    table = b"".join(entries) + np.asarray(crcs, dtype="<u4").tobytes()
    head = struct.pack("<8sHHII", MAGIC, MAJOR, MINOR, len(items), len(crcs))
    hcrc = crc32(head + table)
    return [head + struct.pack("<I", hcrc) + bytes(8) + table] + views


def remove_stale_temps(path: Path) -> None:
    """Delete ``.NAME.tmpPID*`` files beside ``path`` left by writers that no longer run (a
    killed encode); files of live processes are left alone."""
    for t in path.parent.glob(f".{glob_escape(path.name)}.tmp*"):
        digits = t.name[len(path.name) + 5:].split(".")[0]
        if not digits.isdigit():
            continue
        try:
            os.kill(int(digits), 0)
        except ProcessLookupError:
            try:
                t.unlink()
            except OSError:
                pass
        except (PermissionError, OverflowError):
            pass


def glob_escape(name: str) -> str:
    import glob

    return glob.escape(name)


def write_container(path: str | os.PathLike, meta_json: bytes, sections: Iterable[tuple[str, bytes]],
                    chunk_size: int = DEFAULT_CHUNK) -> int:
    """Write a container atomically (temp file in the same folder, fsync, rename).

    Returns:
        the file size in bytes.
    """
    path = Path(path)
    pieces = build_container(meta_json, sections, chunk_size)
    remove_stale_temps(path)
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    try:
        with open(tmp, "wb") as f:
            for p in pieces:
                f.write(p)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
    return sum(len(p) for p in pieces)


class Container:
    """Read a container from a path (memory-mapped), a bytes-like object, or a ByteRangeSource.

    Only the fixed header, the section table and the CRC array are read when opening; sections
    are read (and their chunks verified, once each) on request.

    Raises:
        FormatError / TruncatedError / ChecksumError / UnsupportedError on bad files.
    """

    def __init__(self, source, *, name: str | None = None, partial: bool = False):
        self.partial = partial   # a byte prefix of a file: sections past its end are unavailable
        self._mm = None
        self._file = None
        self._closed = False
        if isinstance(source, (str, os.PathLike)):
            self.name = str(source)
            try:
                # a FIFO would block the open until something writes to it; a device has no size
                if not stat.S_ISREG(os.stat(source).st_mode):
                    raise FormatError(f"{source}: not a regular file (an .lfc file is read from a file, a URL or "
                                      f"bytes)")
                self._file = open(source, "rb")
            except OSError as e:
                raise FormatError(f"{source}: cannot open ({e.strerror})") from None
            except ValueError as e:             # (a NUL byte in the path)
                raise FormatError(f"{source!r}: cannot open ({e})") from None
            size = os.fstat(self._file.fileno()).st_size
            if size == 0:
                self._src = _BufferSource(b"")
            else:
                self._mm = mmap.mmap(self._file.fileno(), 0, access=mmap.ACCESS_READ)
                self._src = _BufferSource(self._mm)
        elif isinstance(source, ByteRangeSource):
            self.name = name or "<byte-range source>"
            self._src = source
        else:
            self.name = name or "<buffer>"
            try:
                self._src = _BufferSource(source)
            except TypeError:
                raise ParameterError(f"an .lfc file is opened from a path, a URL, bytes or a ByteRangeSource, not "
                                     f"{type(source).__name__}") from None
        self.size = self._src.size
        self._verified: set[tuple[str, int]] = set()     # (section, chunk) verified once each
        self._parse_header()

    # -- opening ---------------------------------------------------------------------------
    def _parse_header(self) -> None:
        if self.size < HEADER_SIZE:
            if self.size >= 8 and bytes(self._src.read(0, 8)) != MAGIC:
                raise FormatError(f"{self.name}: not an .lfc file (wrong magic)")
            raise TruncatedError(f"{self.name}: truncated: {self.size} bytes, shorter than the {HEADER_SIZE}-byte header")
        head = bytes(self._src.read(0, HEADER_SIZE))
        magic, major, minor, n_sec, n_crc, hcrc, reserved = _HDR.unpack(head)
        if magic != MAGIC:
            raise FormatError(f"{self.name}: not an .lfc file (wrong magic {magic[:8]!r})")
        if major > MAJOR:
            raise UnsupportedError(f"{self.name}: format version {major}.{minor} is newer than this reader ({MAJOR}.{MINOR}); upgrade lfcodec")
        if major < 1:
            raise FormatError(f"{self.name}: invalid format version {major}.{minor}")
        if n_sec < 1 or n_sec > MAX_SECTIONS:
            raise FormatError(f"{self.name}: header declares {n_sec} sections (allowed 1..{MAX_SECTIONS})")
        table_len = ENTRY_SIZE * n_sec + 4 * n_crc
        if HEADER_SIZE + table_len > self.size:
            raise TruncatedError(f"{self.name}: truncated or corrupt header: section table needs "
                                 f"{HEADER_SIZE + table_len} bytes, file has {self.size}")
        table = bytes(self._src.read(HEADER_SIZE, HEADER_SIZE + table_len))
        if crc32(head[:20] + table) != hcrc:
            raise ChecksumError(f"{self.name}: header/section table checksum mismatch (corrupt header)")
        if reserved != bytes(8):
            raise FormatError(f"{self.name}: header reserved bytes are not zero")
        self.version = (major, minor)
        self._crcs = np.frombuffer(table, dtype="<u4", offset=ENTRY_SIZE * n_sec).copy()
        self.sections: dict[str, SectionInfo] = {}
        expect = HEADER_SIZE + table_len
        next_crc = 0
        for i in range(n_sec):
            raw, off, ln, chunk, first, flags, res = _ENTRY.unpack_from(table, ENTRY_SIZE * i)
            try:
                nm = raw.rstrip(b"\0").decode("ascii")
            except UnicodeDecodeError:
                raise FormatError(f"{self.name}: section {i} has a non-ASCII name") from None
            if not nm or b"\0" in raw.rstrip(b"\0") or not nm.isprintable():
                raise FormatError(f"{self.name}: section {i} has an invalid name {raw!r}")
            info = SectionInfo(nm, off, ln, chunk, first, flags)
            # sections tile the file, and their CRC slots tile the CRC array (no slot shared)
            if chunk == 0 or off != expect or first != next_crc or nm in self.sections:
                raise FormatError(f"{self.name}: section table entry {i} ({nm!r}) is inconsistent "
                                  f"(offset {off}, expected {expect}; first CRC {first}, expected {next_crc}; "
                                  f"chunk {chunk}; duplicate={nm in self.sections})")
            if flags != 0 or res != bytes(4):
                raise FormatError(f"{self.name}: section {nm!r} has nonzero flags/reserved bytes (not defined in "
                                  f"format {MAJOR}.{MINOR})")
            expect = off + ln
            next_crc = first + info.n_chunks
            self.sections[nm] = info
        if next_crc != n_crc:
            raise FormatError(f"{self.name}: the CRC array has {n_crc} slots, the sections use {next_crc}")
        if expect > self.size and self.partial:
            pass
        elif expect > self.size:
            cut = next(s for s in self.sections.values() if s.offset + s.length > self.size)
            raise TruncatedError(f"{self.name}: truncated: section {cut.name!r} ends at byte "
                                 f"{cut.offset + cut.length}, file has {self.size} bytes (a byte prefix of a "
                                 f"progressive file opens with partial=True, or lfcodec's --partial)")
        if expect < self.size:
            raise FormatError(f"{self.name}: {self.size - expect} unexpected bytes after the last section")
        if "meta" not in self.sections:
            raise FormatError(f"{self.name}: no 'meta' section")

    # -- reading -----------------------------------------------------------------------------
    def info(self, name: str) -> SectionInfo:
        try:
            return self.sections[name]
        except KeyError:
            raise FormatError(f"{self.name}: no section {name!r} (has {', '.join(self.sections)})") from None

    def has(self, name: str) -> bool:
        return name in self.sections

    def available(self, name: str) -> bool:
        """The section exists and lies wholly inside the bytes we have (prefix reads)."""
        s = self.sections.get(name)
        return s is not None and s.offset + s.length <= self.size

    def available_bytes(self, name: str) -> int:
        """How many leading bytes of a section can be read and verified from the bytes we have:
        the whole section, or (a byte prefix of the file) up to its last complete chunk."""
        s = self.info(name)
        have = self.size - s.offset
        if have >= s.length:
            return s.length
        return max(have, 0) // s.chunk_size * s.chunk_size

    def _verify(self, info: SectionInfo, c0: int, c1: int, data, base: int) -> None:
        """Check chunks [c0, c1) of a section; ``data`` holds bytes from section offset ``base``."""
        for c in range(c0, c1):
            key = (info.name, c)
            if key in self._verified:
                continue
            a = c * info.chunk_size - base
            b = min((c + 1) * info.chunk_size, info.length) - base
            if crc32(data[a:b]) != int(self._crcs[info.first_crc + c]):
                raise ChecksumError(f"{self.name}: section {info.name!r} is corrupt (checksum mismatch in "
                                    f"chunk {c}, bytes {info.offset + c * info.chunk_size}..{info.offset + b + base})")
            self._verified.add(key)

    def read(self, name: str, start: int = 0, stop: int | None = None, *, verify: bool = True):
        """Bytes [start, stop) of a section, verifying every checksum chunk they touch.

        Returns a bytes-like object (a zero-copy memoryview for memory-mapped files).
        """
        info = self.info(name)
        stop = info.length if stop is None else stop
        if not 0 <= start <= stop <= info.length:
            raise FormatError(f"{self.name}: read [{start}, {stop}) outside section {name!r} of {info.length} bytes")
        if start == stop:
            return b""
        if info.offset + stop > self.size:
            raise TruncatedError(f"{self.name}: section {name!r} is not in the available prefix of the file "
                                 f"({self.size} bytes; it ends at {info.offset + info.length})")
        c0, c1 = start // info.chunk_size, -(-stop // info.chunk_size)
        self.check_unchanged()
        if verify and any((info.name, c) not in self._verified for c in range(c0, c1)):
            a = c0 * info.chunk_size
            b = min(c1 * info.chunk_size, info.length)
            data = self._src.read(info.offset + a, info.offset + b)
            self._verify(info, c0, c1, data, a)
            return data[start - a:stop - a]
        return self._src.read(info.offset + start, info.offset + stop)

    def fetch_ranges(self, name: str, starts, stops) -> int:
        """Ask a remote source to fetch now the checksum chunks that section byte ranges
        [starts[i], stops[i]) touch (those past the available bytes left out), one request per
        run of consecutive chunks not held yet, before the reads that need them (verified when
        read). Returns the requests made: 0 where the source is local or holds them already."""
        if self._closed or not hasattr(self._src, "fetch_ranges"):
            return 0
        info = self.info(name)
        cs, end = info.chunk_size, self.available_bytes(name)
        chunks: set[int] = set()
        for a, b in zip(np.asarray(starts).tolist(), np.asarray(stops).tolist()):
            a, b = max(0, a), min(b, end)
            if b > a:
                chunks.update(range(a // cs, (b - 1) // cs + 1))
        return self._src.fetch_ranges([(info.offset + c * cs, info.offset + min((c + 1) * cs, info.length))
                                       for c in sorted(chunks)])

    def prefetch(self, name: str, start: int = 0, stop: int | None = None) -> int:
        """Ask a remote source to fetch the checksum chunks of section bytes [start, stop) in
        the background (verified when read); the part past the available bytes is left out.
        Returns the bytes asked for: 0 where the source is local or holds them already."""
        info = self.info(name)
        stop = min(info.length if stop is None else stop, self.available_bytes(name))
        if self._closed or not hasattr(self._src, "prefetch") or not 0 <= start < stop:
            return 0                                   # (a closed file fetches nothing; its reads say why)
        a = start // info.chunk_size * info.chunk_size
        b = min(-(-stop // info.chunk_size) * info.chunk_size, info.length)
        return self._src.prefetch(info.offset + a, info.offset + b)

    def array(self, name: str, *, verify: bool = True) -> np.ndarray:
        """A whole section as a read-only uint8 array (zero-copy for memory-mapped files)."""
        return np.frombuffer(self.read(name, verify=verify), dtype=np.uint8)

    def verify_span(self, name: str, start: int, stop: int) -> None:
        """Verify the chunks of one byte range [start, stop) of a section (scalar fast path)."""
        info = self.sections[name]
        self.check_unchanged()
        for c in range(start // info.chunk_size, max(start, stop - 1) // info.chunk_size + 1):
            if (info.name, c) not in self._verified:
                self.read(name, c * info.chunk_size, min((c + 1) * info.chunk_size, info.length))

    def verify_ranges(self, name: str, starts: np.ndarray, stops: np.ndarray) -> None:
        """Verify the chunks touched by many byte ranges [start, stop) of a section, each chunk once."""
        info = self.info(name)
        starts = np.asarray(starts, dtype=np.int64)
        stops = np.asarray(stops, dtype=np.int64)
        if starts.size == 1:                                   # one range: the scalar path
            if stops[0] > starts[0]:
                self.verify_span(name, int(starts[0]), int(stops[0]))
            return
        keep = stops > starts
        if not keep.any():
            return
        c0 = starts[keep] // info.chunk_size
        n = (stops[keep] - 1) // info.chunk_size - c0 + 1
        first = np.repeat(np.cumsum(n) - n, n)
        cs = np.repeat(c0, n) + np.arange(int(n.sum())) - first
        lo = int(cs.min())                                     # each chunk once, ascending (a bincount over the
        chunks = np.flatnonzero(np.bincount(cs - lo)) + lo     # section's chunks: np.unique imports numpy.ma, ~9 ms)
        self.check_unchanged()
        for c in chunks.tolist():
            if (info.name, c) not in self._verified:
                self.read(name, c * info.chunk_size, min((c + 1) * info.chunk_size, info.length))

    def verify_all(self) -> None:
        """Check every chunk of every section (``lfcodec info --verify``)."""
        for info in self.sections.values():
            if info.length:
                self.read(info.name)

    def check_open(self) -> None:
        """A closed container reads nothing more: :meth:`check_unchanged`'s first half, for a
        decode call that reads no bytes of the file (its decoder checks every read it makes)."""
        if self._closed:
            raise ParameterError(f"{self.name}: the file is closed")

    def check_unchanged(self) -> None:
        """A memory-mapped file must still have the size it had when opened (a file truncated
        under a map would kill the process with SIGBUS on the next read of a lost page); and a
        closed container reads nothing more (every read and every decode call checks here)."""
        self.check_open()
        if self._file is not None:
            try:
                size = os.fstat(self._file.fileno()).st_size
            except OSError as e:
                raise FormatError(f"{self.name}: cannot stat the open file ({e.strerror})") from None
            if size != self.size:
                raise FormatError(f"{self.name}: the file changed size while open ({self.size} -> {size} bytes)")

    @property
    def is_remote(self) -> bool:
        """True when bytes come from a byte-range source (fetch per request), not memory."""
        return isinstance(self._src, ByteRangeSource)

    @property
    def bytes_fetched(self) -> int:
        return self._src.bytes_fetched

    def close(self) -> None:
        """Release the file (its map, handle or connection); reads and decodes after this raise
        :class:`~formats.errors.ParameterError`. Closing twice is allowed."""
        self._closed = True
        if self._mm is not None:
            try:
                self._mm.close()
            except BufferError:
                pass  # numpy views still alive; the map closes when they go
            self._mm = None
        if self._file is not None:
            self._file.close()
            self._file = None
        if hasattr(self._src, "close"):
            self._src.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
