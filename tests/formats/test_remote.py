"""Remote reading (issue 16): .lfc files over HTTP byte ranges from `lfcodec serve`'s server
and through fsspec URLs, with a bounded page cache and typed errors for servers that cannot
serve ranges, missing files and files that change while read."""
import os
import shutil
import time
from pathlib import Path

import numpy as np
import pytest

from formats.errors import FormatError, ParameterError
from formats.lfcfile import open_lfc
from formats.registry import open_decoder
from formats.remote import RemoteSource
from formats.serve import FileServer

GOLDEN = Path(__file__).parent.parent / "data" / "golden"
NAME = "rlfc_tx2_lossy_rgba8.lfc"


@pytest.fixture()
def served(tmp_path):
    shutil.copy(GOLDEN / NAME, tmp_path / NAME)
    with FileServer(tmp_path) as srv:
        yield srv, tmp_path


def test_remote_blocks_equal_local_and_fetch_less_than_the_file(served):
    srv, root = served
    local = open_decoder(open_lfc(root / NAME))
    f = open_lfc(srv.url_of(NAME), cache_bytes=1 << 20)
    d = open_decoder(f)
    assert (d.decode_all() == local.decode_all()).all()
    src = f.container._src
    assert isinstance(src, RemoteSource) and src.wire_bytes <= (root / NAME).stat().st_size + src.page
    g = open_lfc(srv.url_of(NAME))                  # a fresh reader: one block costs a few ranges
    d2 = open_decoder(g)
    before = g.container._src.wire_bytes
    blk = d2.decode_block(1, 2, 0, 0)
    assert (blk == local.decode_block(1, 2, 0, 0)).all()
    assert g.container._src.wire_requests <= 12 and g.container._src.wire_bytes - before < os.path.getsize(root / NAME)


def test_page_cache_stays_within_its_budget(served):
    srv, root = served
    src = RemoteSource(srv.url_of(NAME), cache_bytes=4096, page=1024)
    d = open_decoder(open_lfc(src, name=srv.url_of(NAME)))
    for v in range(d.rows * d.cols):
        d.decode_view(v // d.cols, v % d.cols)
        assert src.cached_bytes <= 4096


def test_missing_file_and_rangeless_server_are_typed_errors(tmp_path):
    shutil.copy(GOLDEN / NAME, tmp_path / NAME)
    with FileServer(tmp_path) as srv:
        with pytest.raises(FormatError, match="404"):
            open_lfc(srv.url_of("nope.lfc"))
        with pytest.raises(FormatError, match="404"):
            open_lfc(srv.url_of("../" + tmp_path.name + "/" + NAME + "x"))
    with FileServer(tmp_path, ranges=False) as srv:
        with pytest.raises(FormatError, match="range"):
            open_decoder(open_lfc(srv.url_of(NAME))).decode_all()


def test_file_changed_on_the_server_is_a_typed_error(served):
    srv, root = served
    d = open_decoder(open_lfc(RemoteSource(srv.url_of(NAME), cache_bytes=1024, page=512)))
    data = (root / NAME).read_bytes()
    time.sleep(0.01)
    (root / NAME).write_bytes(data[:-1] + bytes([data[-1] ^ 1]))   # same size, new content and mtime
    with pytest.raises(FormatError, match="changed"):
        for v in range(d.rows * d.cols):
            d.decode_view(v // d.cols, v % d.cols)


def test_prefetch_fills_the_cache_within_budget_and_errors_reach_the_read(served):
    """Prefetched pages serve later reads without a request of their own, stay within the page
    budget, and a file changed on the server while prefetching is the read's typed error."""
    srv, root = served
    data = (root / NAME).read_bytes()
    src = RemoteSource(srv.url_of(NAME), cache_bytes=4096, page=512)
    assert src.wire_requests == 1 and src.cached_bytes == 512    # the size and the first page: one request
    assert src.prefetch(0, 10 ** 9) == 1536                  # at most half the budget at once (page 0 held)
    src.wait_prefetch()
    assert src.prefetched_bytes == 1536 and src.prefetch(0, 2048) == 0 and src.cached_bytes <= 4096
    n = src.read_requests
    assert src.read(100, 2000) == data[100:2000] and src.read_requests == n      # served from the cache
    assert src.read(1000, 3000) == data[1000:3000] and src.read_requests == n + 1
    time.sleep(0.01)
    (root / NAME).write_bytes(data[:-1] + bytes([data[-1] ^ 1]))   # same size, new content and mtime
    assert src.prefetch(len(data) - 600, len(data)) > 0
    src.wait_prefetch()                                      # the prefetch failed in the background
    with pytest.raises(FormatError, match="changed"):
        src.read(len(data) - 600, len(data))
    src.close()


def test_prefetch_worker_is_a_daemon_and_close_drops_queued_runs(served):
    """The prefetch thread does not hold the interpreter open at exit (a daemon); close() waits
    for the request under way and drops the runs not started; reads still work after it."""
    srv, root = served
    data = (root / NAME).read_bytes()
    src = RemoteSource(srv.url_of(NAME), cache_bytes=8192, page=512, latency_s=0.2)
    assert src.prefetch(512, 1024) == 512 and src.prefetch(2048, 2560) == 512   # two runs, two jobs
    assert src._worker.daemon
    time.sleep(0.05)                                          # the first run is under way
    src.close()
    assert src.prefetched_bytes == 512 and not src._inflight and src._worker is None
    n = src.read_requests
    assert src.read(2048, 2560) == data[2048:2560] and src.read_requests == n + 1  # fetched by the read itself
    assert src.prefetch(4096, 4608) == 512
    src.wait_prefetch()
    assert src.prefetched_bytes == 1024
    src.close()


def test_fsspec_file_url(tmp_path):
    shutil.copy(GOLDEN / NAME, tmp_path / NAME)
    d = open_decoder(open_lfc((tmp_path / NAME).as_uri()))
    assert (d.decode_all() == open_decoder(open_lfc(tmp_path / NAME)).decode_all()).all()
    with pytest.raises(FormatError):
        open_lfc((tmp_path / "missing.lfc").as_uri())


def test_cli_info_over_http(served, capsys):
    from formats.cli import main

    srv, _ = served
    assert main(["info", srv.url_of(NAME), "--verify"]) == 0
    assert main(["decode", srv.url_of(NAME), "--block", "0,0,0,0", "--out", str(served[1] / "b.npy"),
                 "--quiet"]) == 0
    assert np.load(served[1] / "b.npy").shape[-1] == 4


def test_lfn_streams_progressively_over_http(tmp_path):
    """An LFN read over HTTP fetches the sections its level needs, and more as the level rises
    (issue 16); the grown network renders exactly as one opened with that many neurons."""
    from formats.cli import main
    from formats.scenes import write_views
    from lfn_stream.render import LfnRenderer
    from tests.rlfc.helpers import smooth_lf

    lf = smooth_lf(rows=2, cols=2, h=16, w=16)
    write_views(tmp_path / "scene", lf.views)
    lfn = "n.lfc"
    assert main(["train", str(tmp_path / "scene"), str(tmp_path / lfn), "--grid", "2x2", "--steps", "1",
                 "--max-neurons", "64", "--min-neurons", "16", "--quiet"]) == 0
    size = (tmp_path / lfn).stat().st_size
    with FileServer(tmp_path) as srv:
        f = open_lfc(srv.url_of(lfn), cache_bytes=4096)           # 4 KiB pages, one page cached
        src = f.container._src
        r = LfnRenderer(f, device="cpu", max_neurons=18, prefetch=0)
        assert r.neurons == 18
        small = src.wire_bytes
        assert small < size / 2                                 # the later steps were not fetched
        assert r.grow(40) == 40 and small < src.wire_bytes < size
        assert r.grow() == 64
        ref = LfnRenderer(open_lfc(tmp_path / lfn), device="cpu", max_neurons=40)
        r40 = LfnRenderer(open_lfc(srv.url_of(lfn)), device="cpu", max_neurons=18)
        r40.grow(40)
        assert np.array_equal(r40.render(0, 1, neurons=33.5), ref.render(0, 1, neurons=33.5))
        with pytest.raises(ParameterError):
            r.grow(float("nan"))
        # prefetch: after each read the next steps come in the background, so growing into
        # them makes no request of its own; the pixels are those of a local file
        for ahead, free in ((0, False), (8, True)):
            src = RemoteSource(srv.url_of(lfn), cache_bytes=1 << 20, page=512)
            r = LfnRenderer(open_lfc(src, name=lfn), device="cpu", max_neurons=18, prefetch=ahead)
            src.wait_prefetch()
            n0 = src.read_requests
            assert r.grow(26) == 26 and (src.read_requests == n0) == free, ahead
            ref = LfnRenderer(open_lfc(tmp_path / lfn), device="cpu", max_neurons=26)
            assert np.array_equal(r.render(1, 0, neurons=25.25), ref.render(1, 0, neurons=25.25))
            src.wait_prefetch()
            assert (src.prefetched_bytes > 0) == free and src.cached_bytes <= src.cache_bytes
            n0 = src.read_requests
            assert r.grow() == 64 and src.read_requests > n0       # beyond what was prefetched
            src.close()
        with pytest.raises(ParameterError):
            LfnRenderer(open_lfc(tmp_path / lfn), device="cpu", prefetch=-1)


@pytest.mark.parametrize("rng,code,body", [("bytes=0-3", 206, (0, 4)), ("bytes=-4", 206, (-4, None)),
                                           ("bytes=2-", 206, (2, None)), ("bytes=0-3,10-12", 200, (0, None)),
                                           ("bytes=5-2", 416, None), ("bytes=99999999-", 416, None),
                                           ("items=0-3", 416, None)])
def test_server_ranges(served, rng, code, body):
    # one range: 206; several: ignored, the whole file (416 used to say a satisfiable request was
    # not); malformed or past the end: 416
    import urllib.error
    import urllib.request

    srv, root = served
    data = (root / NAME).read_bytes()
    req = urllib.request.Request(srv.url_of(NAME), headers={"Range": rng})
    try:
        with urllib.request.urlopen(req) as r:
            got, status = r.read(), r.status
    except urllib.error.HTTPError as e:
        got, status = None, e.code
    assert status == code
    if body is not None:
        assert got == data[body[0]:body[1]]


def test_serve_on_a_port_in_use_is_one_line(tmp_path, capsys):
    """A port another server holds: a ParameterError naming host and port (before: the bare
    'Address already in use')."""
    from formats.cli import main
    from formats.errors import ParameterError
    from formats.serve import FileServer

    with FileServer(tmp_path) as srv:
        with pytest.raises(ParameterError, match=f"cannot listen on 127.0.0.1:{srv.port}"):
            FileServer(tmp_path, port=srv.port)
        assert main(["serve", str(tmp_path), "--port", str(srv.port)]) == 2
        err = capsys.readouterr().err
        assert len(err.splitlines()) == 1 and "give another --port" in err


def test_a_calls_streams_come_in_one_request_per_run_of_missing_chunks(tmp_path, monkeypatch):
    """A decode call's residual streams (here every block of three views with references, in
    a file of 512-byte checksum chunks read through 512-byte pages) are fetched before they are
    read, one request per run of consecutive missing chunks (Container.fetch_ranges), not one
    per run of streams in turn: fewer requests, the same pixels as the local file."""
    from formats.container import Container
    from formats.lfcfile import write_lfc
    from rlfc import encode
    from tests.rlfc.helpers import smooth_lf

    lf = smooth_lf(rows=3, cols=3, h=64, w=64)
    noisy = lf.views.astype(np.int16) + np.random.default_rng(1).integers(-12, 13, lf.views.shape)
    lf.views[...] = np.clip(noisy, 0, 255).astype(np.uint8)
    e = encode(lf, profile="tx", step=3.0)
    write_lfc(tmp_path / "n.lfc", "rlfc", 1, e.config, lf.geometry(), e.sections, chunk_size=512)
    local = open_decoder(open_lfc(tmp_path / "n.lfc"))
    views = [v for v in range(9) if not local.core.is_key[v] and local.core.coded[v].any()][:3]
    assert len(views) == 3
    nb = local.nby * local.nbx
    req = (np.repeat(views, nb), np.tile(np.arange(nb) // local.nbx, 3), np.tile(np.arange(nb) % local.nbx, 3))
    want = local.decode_blocks(*req)
    counts = []
    with FileServer(tmp_path) as srv:
        for ahead in (True, False):
            if not ahead:
                monkeypatch.setattr(Container, "fetch_ranges", lambda self, *a: 0)
            src = RemoteSource(srv.url_of("n.lfc"), cache_bytes=1 << 22, page=512)
            d = open_decoder(open_lfc(src, name="n.lfc"))
            d.decode_keys()
            d.decode_maps()
            before = src.read_requests
            assert (d.decode_blocks(*req) == want).all()
            counts.append(src.read_requests - before)
    assert 1 <= counts[0] < counts[1], counts


def test_the_size_comes_with_the_first_bytes(served):
    """Over HTTP one range GET gives the file's size (Content-Range), version (ETag) and first
    bytes, where a HEAD and then a read took two round trips; the HEAD stays for servers whose
    answer gives no total size (and for a first of 0 bytes)."""
    from formats.remote import _Http

    srv, root = served
    data = (root / NAME).read_bytes()
    h = _Http(srv.url_of(NAME), 30.0, 512)
    assert h.size == len(data) and h.first == data[:512] and h.tag
    assert _Http(srv.url_of(NAME), 30.0, 10 ** 7).first == data          # (a file under one page: all of it)
    head = _Http(srv.url_of(NAME), 30.0)
    assert head.size == len(data) and head.first is None and head.tag == h.tag
    assert head.fetch(100, 300) == data[100:300]
