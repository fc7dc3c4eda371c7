"""Remote ``.lfc`` files read by byte ranges, through a page cache with a byte budget.

``open_remote(url)`` gives a :class:`~formats.container.ByteRangeSource` that
:class:`~formats.container.Container` reads like any other: only the header, the section
table and the chunks a request touches are fetched, and every fetched chunk is verified
against its CRC before use.

- ``http://`` / ``https://``: the standard library's HTTP client, one ``Range`` request per
  run of missing pages. The server must answer ``206 Partial Content`` with the asked
  ``Content-Range``; the file's ``ETag`` (or ``Last-Modified``) seen at open is sent as
  ``If-Match`` / checked on every response, so a file replaced on the server between
  requests is a :class:`~formats.errors.FormatError`, never a mix of two files. (HTTP is done
  here rather than through fsspec so that these rules are enforced: fsspec's HTTP backend
  accepts a ``200`` full-body answer to a range request.)
- any other scheme fsspec knows (``file://``, ``s3://``, ``gs://``, ``memory://``, …):
  ``fs.cat_file(path, start, end)``; the size is checked on every read.

Fetched pages live in an LRU cache of at most ``cache_bytes`` bytes, so a session that sweeps
a whole file never holds more than that (plus the pages of the request being served).
:meth:`RemoteSource.prefetch` fetches a byte range into that cache on a background thread (a
reader that needs a page being prefetched waits for it instead of asking again); prefetched
bytes are verified when they are read, like any other.
"""
from __future__ import annotations

import collections
import queue
import threading
import time
from concurrent.futures import Future
import urllib.error
import urllib.request

from .container import ByteRangeSource
from .errors import FormatError, LfcError, TruncatedError

DEFAULT_PAGE = 1 << 16
DEFAULT_CACHE = 64 << 20
#: concurrent range requests of :meth:`RemoteSource.fetch_ranges` (separate runs of pages)
FETCH_THREADS = 4


def is_url(source) -> bool:
    """True for strings with a URL scheme (``scheme://``), other than a Windows drive path."""
    return isinstance(source, str) and "://" in source and len(source.split("://", 1)[0]) > 1


class _Http:
    """Range requests over HTTP(S) with the rules in the module doc."""

    def __init__(self, url: str, timeout: float, first: int = 0):
        """``first``: the file's first bytes are asked for in the request that learns its size
        and version (a range GET: its Content-Range gives the size, one round trip, not a HEAD
        and then a read; ``self.first`` holds them); 0, or a server whose answer gives no total
        size: a HEAD."""
        self.url, self.timeout = url, timeout
        self.first = None
        if first > 0:
            with self._open(urllib.request.Request(url, headers={"Range": f"bytes=0-{first - 1}"})) as r:
                self._expect_partial(r)
                cr = r.headers.get("Content-Range", "")
                total = cr.rsplit("/", 1)[-1] if cr.startswith("bytes ") else ""
                self._tag_from(r.headers)
                if total.isdigit():
                    data = r.read()
                    self.size = int(total)
                    if cr != f"bytes 0-{len(data) - 1}/{self.size}" or len(data) != min(first, self.size):
                        raise FormatError(f"{url}: the server answered range {cr!r} with {len(data)} bytes for "
                                          f"bytes 0-{first - 1}")
                    self.first = data
                    return
        with self._open(urllib.request.Request(url, method="HEAD")) as r:
            size = r.headers.get("Content-Length")
            self._tag_from(r.headers)
            ranges = r.headers.get("Accept-Ranges", "")
        if size is None or not size.isdigit():
            raise FormatError(f"{url}: the server gives no Content-Length; byte-range reading needs one")
        if ranges.strip().lower() == "none":
            raise FormatError(f"{url}: the server does not support byte ranges (Accept-Ranges: none)")
        self.size = int(size)

    def _expect_partial(self, r) -> None:
        """A range request's answer must be 206 Partial Content (a 200 is the whole file: the
        server does not serve ranges)."""
        if r.status != 206:
            raise FormatError(f"{self.url}: the server ignored the byte range (HTTP {r.status} instead of 206); "
                              f"it does not support range requests")

    def _tag_from(self, headers) -> None:
        """The file's version (ETag, else Last-Modified) that every later range must match."""
        etag, modified = headers.get("ETag"), headers.get("Last-Modified")
        self.tag = etag or modified
        self.condition = "If-Match" if etag else "If-Unmodified-Since"

    def _open(self, req):
        try:
            return urllib.request.urlopen(req, timeout=self.timeout)
        except urllib.error.HTTPError as e:
            if e.code == 412:
                raise FormatError(f"{self.url}: the file changed on the server while it was being read "
                                  f"(ETag no longer matches)") from None
            if e.code == 416:
                raise TruncatedError(f"{self.url}: the server says the range is outside the file (416); "
                                     f"the file may have been truncated") from None
            raise FormatError(f"{self.url}: HTTP {e.code} {e.reason}") from None
        except (urllib.error.URLError, OSError) as e:
            raise FormatError(f"{self.url}: cannot fetch ({getattr(e, 'reason', e)})") from None

    def fetch(self, start: int, stop: int) -> bytes:
        headers = {"Range": f"bytes={start}-{stop - 1}"}
        if self.tag:
            headers[self.condition] = self.tag
        with self._open(urllib.request.Request(self.url, headers=headers)) as r:
            self._expect_partial(r)
            cr = r.headers.get("Content-Range", "")
            tag = r.headers.get("ETag") or r.headers.get("Last-Modified")
            if self.tag and tag and tag != self.tag:
                raise FormatError(f"{self.url}: the file changed on the server while it was being read")
            if cr != f"bytes {start}-{stop - 1}/{self.size}":
                raise FormatError(f"{self.url}: the server answered range {cr!r} for bytes {start}-{stop - 1} "
                                  f"of {self.size} (the file may have changed)")
            data = r.read()
        if len(data) != stop - start:
            raise TruncatedError(f"{self.url}: got {len(data)} bytes for range [{start}, {stop})")
        return data


class _Fsspec:
    """Byte ranges through an fsspec filesystem."""

    def __init__(self, url: str):
        try:
            import fsspec
        except ImportError:
            raise FormatError(f"{url}: reading this kind of URL needs fsspec (pip install fsspec)") from None
        try:
            self.fs, self.path = fsspec.core.url_to_fs(url)
            self.size = int(self.fs.size(self.path))
        except (ValueError, ImportError) as e:
            raise FormatError(f"{url}: unsupported URL ({e})") from None
        except (OSError, KeyError) as e:
            raise FormatError(f"{url}: cannot open ({e})") from None
        self.url = url

    def fetch(self, start: int, stop: int) -> bytes:
        try:
            data = self.fs.cat_file(self.path, start=start, end=stop)
        except (OSError, KeyError, ValueError) as e:
            raise FormatError(f"{self.url}: cannot read bytes [{start}, {stop}) ({e})") from None
        if len(data) != stop - start:
            raise TruncatedError(f"{self.url}: got {len(data)} bytes for range [{start}, {stop}); the file may "
                                 f"have changed")
        return data


class RemoteSource(ByteRangeSource):
    """A remote file as a byte-range source with an LRU page cache.

    Args:
        url: http(s):// or any fsspec URL.
        cache_bytes: the most bytes of fetched pages kept (≥ one page).
        page: page size in bytes (default 64 KiB, or the budget when smaller; reads are
            rounded out to whole pages and runs of missing pages are fetched in one request each).
        latency_s: added before every request (to stand for a network in benchmarks).
        timeout: seconds per HTTP request.

    Attributes:
        wire_bytes, wire_requests: what went over the wire (prefetches included); read_requests:
        the requests reads made and waited for; prefetched_bytes: bytes fetched ahead;
        bytes_fetched, requests: what the reader asked for (cache hits included); cached_bytes:
        what the cache holds.
    """

    def __init__(self, url: str, *, cache_bytes: int = DEFAULT_CACHE, page: int | None = None,
                 latency_s: float = 0.0, timeout: float = 30.0):
        page = page or max(512, min(DEFAULT_PAGE, cache_bytes))
        if page < 512 or cache_bytes < page:
            raise ValueError("page must be >= 512 bytes and cache_bytes >= page")
        # (over HTTP(S) the first page comes with the size, in one request: every open reads it)
        self.backend = _Http(url, timeout, page) if url.lower().startswith(("http://", "https://")) else _Fsspec(url)
        super().__init__(self._read_pages, self.backend.size)
        self.url, self.page, self.cache_bytes, self.latency_s = url, page, cache_bytes, latency_s
        self._pages: collections.OrderedDict[int, bytes] = collections.OrderedDict()
        self._inflight: dict[int, Future] = {}         # page -> the prefetch fetching it
        self._lock = threading.Lock()
        self._jobs: queue.SimpleQueue | None = None     # (future, first page, last page) for the worker
        self._worker: threading.Thread | None = None
        self.cached_bytes = 0
        self.wire_bytes = 0
        self.wire_requests = 0
        self.prefetched_bytes = 0
        self.read_requests = 0
        first = getattr(self.backend, "first", None)
        if first:                                       # (the page the size request brought)
            self._store({0: first})
            self.wire_bytes, self.wire_requests = len(first), 1

    def _get(self, a: int, b: int) -> bytes:
        if self.latency_s:
            time.sleep(self.latency_s)
        data = self.backend.fetch(a, b)
        with self._lock:
            self.wire_bytes += len(data)
            self.wire_requests += 1
        return data

    def _runs(self, pages: list[int]) -> list[tuple[int, int]]:
        """Runs [first, last] of consecutive page numbers."""
        runs, i = [], 0
        while i < len(pages):
            j = i
            while j + 1 < len(pages) and pages[j + 1] == pages[j] + 1:
                j += 1
            runs.append((pages[i], pages[j]))
            i = j + 1
        return runs

    def _fetch_run(self, first: int, last: int) -> dict[int, bytes]:
        P = self.page
        data = self._get(first * P, min((last + 1) * P, self.size))
        return {p: data[(p - first) * P:(p - first + 1) * P] for p in range(first, last + 1)}

    def _store(self, got: dict[int, bytes]) -> None:
        """Cache pages (lock held), evicting the least recently used beyond the budget."""
        for p, data in got.items():
            if p not in self._pages:
                self._pages[p] = data
                self.cached_bytes += len(data)
        while self.cached_bytes > self.cache_bytes and self._pages:
            _, old = self._pages.popitem(last=False)
            self.cached_bytes -= len(old)

    def _read_pages(self, start: int, stop: int) -> bytes:
        if not 0 <= start <= stop <= self.size:
            raise TruncatedError(f"{self.url}: range [{start}, {stop}) outside the file of {self.size} bytes")
        if start == stop:
            return b""
        P = self.page
        p0, p1 = start // P, (stop - 1) // P + 1
        got: dict[int, bytes] = {}
        with self._lock:
            for p in range(p0, p1):
                if p in self._pages:
                    self._pages.move_to_end(p)
                    got[p] = self._pages[p]
            waits = {p: self._inflight[p] for p in range(p0, p1) if p not in got and p in self._inflight}
        for p, fut in waits.items():                   # pages a prefetch is fetching: wait for it
            try:
                got[p] = fut.result()[p]
            except Exception:                          # noqa: BLE001 -- fetched again below, where an
                pass                                   # error is raised as this read's own
        missing = [p for p in range(p0, p1) if p not in got]
        for first, last in self._runs(missing):        # one request per run of missing pages
            got.update(self._fetch_run(first, last))
            self.read_requests += 1
        with self._lock:
            self._store({p: got[p] for p in missing})
        out = b"".join(got[p] for p in range(p0, p1))
        return out[start - p0 * P:stop - p0 * P]

    def fetch_ranges(self, ranges) -> int:
        """Fetch now the pages of byte ranges ``ranges`` ([(start, stop), …]) that are neither
        cached nor being fetched: one request per run of consecutive missing pages, the runs of an
        HTTP(S) source on up to FETCH_THREADS requests at once. For a reader that knows its next
        reads (the streams a decode call parses): they then find their pages cached, instead of
        each waiting for a request of its own in turn. At most half the cache budget is fetched
        (the rest is left to the reads). Returns the requests made."""
        P = self.page
        want: set[int] = set()
        for a, b in ranges:
            a, b = max(0, int(a)), min(int(b), self.size)
            if b > a:
                want.update(range(a // P, (b - 1) // P + 1))
        with self._lock:
            pages = sorted(p for p in want if p not in self._pages and p not in self._inflight)
        runs = self._runs(pages[:max(1, self.cache_bytes // 2 // P)])
        if not runs:
            return 0
        got: dict[int, bytes] = {}
        if len(runs) > 1 and isinstance(self.backend, _Http):
            from concurrent.futures import ThreadPoolExecutor

            with ThreadPoolExecutor(min(FETCH_THREADS, len(runs))) as ex:
                for part in ex.map(lambda r: self._fetch_run(*r), runs):
                    got.update(part)
        else:
            for r in runs:
                got.update(self._fetch_run(*r))
        with self._lock:
            self._store(got)
            self.read_requests += len(runs)
        return len(runs)

    def prefetch(self, start: int, stop: int) -> int:
        """Fetch the pages of bytes [start, stop) that are neither cached nor being fetched, on a
        background thread, one request per run; at most half the cache budget is prefetched at
        once (the rest is cut). Returns the bytes asked for (0: nothing to do). Errors surface
        when a read needs those pages."""
        start, stop = max(0, int(start)), min(int(stop), self.size, int(start) + self.cache_bytes // 2)
        if stop <= start:
            return 0
        P = self.page
        with self._lock:
            pages = [p for p in range(start // P, (stop - 1) // P + 1) if p not in self._pages and p not in self._inflight]
            if not pages:
                return 0
            if self._worker is None:
                # a daemon thread: an interpreter that exits during a slow request does not wait for it
                self._jobs = queue.SimpleQueue()
                self._worker = threading.Thread(target=self._work, args=(self._jobs,), name="lfc-prefetch",
                                                daemon=True)
                self._worker.start()
            for first, last in self._runs(pages):
                fut: Future = Future()
                for p in range(first, last + 1):
                    self._inflight[p] = fut
                self._jobs.put((fut, first, last))
        return len(pages) * P

    def wait_prefetch(self, timeout: float | None = None) -> None:
        """Block until the prefetches under way have finished (benchmarks, tests)."""
        with self._lock:
            futs = set(self._inflight.values())
        for fut in futs:
            try:
                fut.result(timeout)
            except Exception:                          # noqa: BLE001 -- a read raises it, if it needs the bytes
                pass

    def _work(self, jobs: queue.SimpleQueue) -> None:
        """The prefetch worker: runs jobs in order until a None."""
        while (job := jobs.get()) is not None:
            fut, first, last = job
            if fut.set_running_or_notify_cancel():
                try:
                    fut.set_result(self._prefetch_run(first, last))
                except BaseException as e:             # noqa: BLE001 -- handed to whoever waits on it
                    fut.set_exception(e)
            else:                                      # cancelled by close()
                self._forget(fut, first, last)

    def _forget(self, fut: Future, first: int, last: int) -> None:
        with self._lock:
            for p in range(first, last + 1):
                if self._inflight.get(p) is fut:
                    del self._inflight[p]

    def _prefetch_run(self, first: int, last: int) -> dict[int, bytes]:
        try:
            got = self._fetch_run(first, last)
            with self._lock:
                self._store(got)
                self.prefetched_bytes += sum(len(v) for v in got.values())
            return got
        finally:
            with self._lock:
                for p in range(first, last + 1):
                    self._inflight.pop(p, None)

    def close(self) -> None:
        """Stop prefetching: prefetches not started are dropped; waits for a request under way."""
        if self._worker is not None:
            with self._lock:
                for fut in set(self._inflight.values()):
                    fut.cancel()
            self._jobs.put(None)
            self._worker.join()
            self._worker = self._jobs = None


def open_remote(url: str, **kw) -> RemoteSource:
    """A :class:`RemoteSource` for ``url`` (see its arguments); errors are LfcErrors."""
    try:
        return RemoteSource(url, **kw)
    except LfcError:
        raise
    except ValueError as e:
        raise FormatError(f"{url}: {e}") from None
