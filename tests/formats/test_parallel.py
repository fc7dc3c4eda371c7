"""Parallel encode: runners, and the same file whatever runs the encode (serial, a local pool,
a dask.distributed LocalCluster)."""
import numpy as np
import pytest

from formats.codec_api import EncodeOptions
from formats.errors import LfcError, ParameterError, WorkerError
from formats.parallel import PoolRunner, Runner, check_runner, make_runner
from formats.scenes import read_scene
from rlfc.codec import RlfcCodec
from tests.conftest import ROOT

SAMPLE = ROOT / "samples" / "dino_crop"


def _scale(x, k):
    return x * k


def _fail(x):
    if x == 2:
        raise ParameterError(f"task {x} refuses")
    return x


@pytest.mark.parametrize("workers,scheduler,needle", [
    (0, None, "1..256"), (257, None, "1..256"), (True, None, "1..256"), (1.5, None, "1..256"),
    (2, "tcp://127.0.0.1:8786", "not both"), (1, "not an address", "address"),
])
def test_bad_runner_options(workers, scheduler, needle):
    with pytest.raises(ParameterError, match=needle):
        check_runner(workers, scheduler)


def test_serial_runner_is_a_loop():
    r = make_runner(1)
    assert type(r) is Runner and r.map(_scale, [(1, r.share(3)), (2, 3)]) == [3, 6]


def test_pool_shares_objects_keeps_order_and_passes_typed_errors():
    with PoolRunner(2) as r:
        k = r.share(np.arange(5))
        out = r.map(_scale, [(i, k) for i in range(6)])
        assert [o.tolist() for o in out] == [(i * np.arange(5)).tolist() for i in range(6)]
        with pytest.raises(ParameterError, match="task 2 refuses"):
            r.map(_fail, [(i,) for i in range(4)])


def test_take_sees_each_result_as_it_arrives_and_its_value_is_kept():
    """``take(i, result)`` (the encoder moves each view's pixels into one buffer with it): called
    once per task with the task's index, on every runner, and its value replaces the result."""
    seen = []

    def take(i, r):
        seen.append(i)
        return (i, r)

    want = [(i, i * 3) for i in range(5)]
    assert Runner().map(_scale, [(i, 3) for i in range(5)], take=take) == want
    assert Runner().map_threaded(_scale, [(i, 3) for i in range(5)], threads=2, take=take) == want
    with PoolRunner(2) as r:
        assert r.map(_scale, [(i, 3) for i in range(5)], take=take) == want
    assert sorted(seen) == sorted(list(range(5)) * 3)


def _dag_task(i, log, lock, fail=None):
    with lock:
        log.append(("start", i))
    if i == fail:
        raise ParameterError(f"task {i} refuses")
    return i * 10


@pytest.mark.parametrize("threads", [1, 2, 3])
def test_map_dag_waits_on_dependencies_and_keeps_order(threads):
    """``map_dag``: results in index order, equal to the loop; no task starts before every
    task it waits on has finished and been through ``finish``; the lowest-indexed ready task
    goes first; a task's error comes back as it was raised; a dependency on a later task is
    refused."""
    import threading

    deps = [[], [0], [0, 1], [0, 1], [2, 3], [1, 2], [3], [5, 6], [0]]
    log, lock = [], threading.Lock()

    def finish(i, r):
        with lock:
            log.append(("finish", i))
        return (i, r)

    out = Runner().map_dag(_dag_task, [(i, log, lock) for i in range(len(deps))], deps, finish, threads=threads)
    assert out == [(i, i * 10) for i in range(len(deps))]
    at = {e: n for n, e in enumerate(log)}
    for i, d in enumerate(deps):
        assert all(at[("finish", j)] < at[("start", i)] for j in d)
    if threads == 1:
        assert [e for e in log if e[0] == "start"] == [("start", i) for i in range(len(deps))]
    with pytest.raises(ParameterError, match="task 4 refuses"):
        Runner().map_dag(_dag_task, [(i, [], lock, 4) for i in range(len(deps))], deps, threads=threads)
    with pytest.raises(ValueError, match="before it"):
        Runner().map_dag(_dag_task, [(i, [], lock) for i in range(3)], [[], [2], []], threads=threads)


@pytest.fixture(scope="module")
def small_lf():
    lf = read_scene(SAMPLE)
    lf.views = np.ascontiguousarray(lf.views[:5, :5, :64, :96])     # 5x5 views of 64x96
    return lf


def _encode(lf, **kw):
    # (at 36 dB the maps' corrections are repriced at the coding λ: the workers code with the
    # maps that decision left)
    enc = RlfcCodec().encode(lf, EncodeOptions(target_psnr=36, **kw))
    return b"".join(bytes(x) for _, x in enc.sections), enc


@pytest.fixture(scope="module")
def serial_file(small_lf):
    return _encode(small_lf)


def test_pool_encode_is_the_same_file(small_lf, serial_file):
    assert serial_file[1].summary["params"]["maps_repriced"] is not None
    blob, enc = _encode(small_lf, workers=2)
    assert enc.summary["runner"] == "pool" and enc.summary["workers"] == 2
    assert blob == serial_file[0]
    assert np.array_equal(enc.decoded, serial_file[1].decoded)


@pytest.mark.parametrize("threads", [1, 3])
def test_threads_of_a_pass_give_the_same_file(small_lf, serial_file, monkeypatch, threads):
    """A pass's predicted keys and other views run as tasks that wait on the keys they predict
    from, on LOCAL_THREADS threads: the same file whatever their number, also where every
    predicted key is tried as JPEG 2000 (each search starts from the intra key's, not from
    whichever key finished last)."""
    import formats.parallel as par
    from rlfc.txencode import TxEncoder

    monkeypatch.setattr(par, "LOCAL_THREADS", threads)
    assert _encode(small_lf)[0] == serial_file[0]
    monkeypatch.setattr(TxEncoder, "J2K_TRY_SHARE", 0.0)
    blob = _encode(small_lf)[0]
    monkeypatch.setattr(par, "LOCAL_THREADS", 2)
    assert blob == _encode(small_lf)[0]


def test_keys_one_after_another_where_there_is_no_atlas(small_lf, serial_file, monkeypatch):
    """Views OpenCV cannot sample (no key atlas: a planar copy of the key views, rebuilt key by
    key) code the keys one after another: the same integers, the same file."""
    from rlfc.txencode import TxEncoder

    monkeypatch.setattr(TxEncoder, "key_atlas", lambda self, n: None)
    assert _encode(small_lf)[0] == serial_file[0]


def test_dask_local_cluster_encode_is_the_same_file(small_lf, serial_file):
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cl:
        # an address, as `lfcodec encode --scheduler` gives it: the runner connects (no default
        # client exists) and closes its own client
        blob2, enc2 = _encode(small_lf, scheduler=cl.scheduler_address)
        assert blob2 == serial_file[0] and enc2.summary["runner"] == "dask"
        with distributed.Client(cl) as client:
            blob, enc = _encode(small_lf, scheduler=client)
            assert enc.summary["runner"] == "dask" and enc.summary["workers"] == 2
            assert blob == serial_file[0]


def test_unreachable_scheduler_is_a_worker_error(monkeypatch):
    pytest.importorskip("distributed")
    import formats.parallel as par

    monkeypatch.setattr(par, "CONNECT_TIMEOUT", "1s")
    with pytest.raises(WorkerError, match="cannot reach"):
        make_runner(1, "tcp://127.0.0.1:9")
    assert issubclass(WorkerError, LfcError)


def test_pool_encode_of_views_left_in_their_files_is_the_same_file(small_lf, serial_file, tmp_path):
    """Views read from their files as the encoder asks (``lfcodec encode``'s way), the pool's
    workers reading the views they code themselves: the same file as the serial encode from
    memory, and the parent decodes no view a third time (it did, to ship the pixels)."""
    from formats.imageio import write_image

    for i in range(25):
        write_image(tmp_path / f"input_Cam{i:03d}.png", small_lf.views[i // 5, i % 5])
    lf = read_scene(tmp_path, lazy=True)
    assert not isinstance(lf.views, np.ndarray)
    blob, enc = _encode(lf, workers=2)
    assert enc.summary["runner"] == "pool" and blob == serial_file[0]
    # the parent: every view once for the maps, the search's keys and sample once more
    assert lf.views.arr.decodes < 2 * 25


def _blas_threads(_):
    from threadpoolctl import threadpool_info

    return sorted({d["num_threads"] for d in threadpool_info() if d["user_api"] == "blas"})


@pytest.mark.parametrize("how", ["map_threaded", "map_dag"])
def test_tasks_on_threads_get_one_blas_thread_each(how):
    """Tasks on the runner's threads see numpy's BLAS on one thread (our threads are the
    parallelism; its own threads spin beside them), and the caller's setting comes back after."""
    import cv2  # noqa: F401  (its own OpenBLAS loads with it: loaded before the limits below are set)
    from threadpoolctl import threadpool_limits

    with threadpool_limits(2, user_api="blas"):
        assert _blas_threads(0) == [2]
        args = [(i,) for i in range(4)]
        got = (Runner().map_threaded(_blas_threads, args, threads=2) if how == "map_threaded"
               else Runner().map_dag(_blas_threads, args, [[]] * 4, threads=2))
        assert got == [[1]] * 4
        assert _blas_threads(0) == [2]


def test_an_encode_runs_with_one_blas_thread(monkeypatch):
    """The whole encode (main thread included) sees numpy's BLAS on one thread: a GEMM's floats
    then do not depend on how many threads the BLAS library would take on this machine, so
    neither does the file (epfl_iso_chart_1 at 40 dB came out 45 bytes apart with 1 and 2)."""
    import rlfc.codec as rc
    from threadpoolctl import threadpool_limits

    seen = []

    class Probe:
        def encode(self, lf, options, progress=None):
            seen.append(_blas_threads(0))
            raise ParameterError("probe")

    monkeypatch.setattr(rc, "get_profile", lambda pid: Probe())
    monkeypatch.setattr(rc, "choose_profile", lambda lf, requested: "tx")
    lf = read_scene(SAMPLE)
    import cv2  # noqa: F401  (as above)
    with threadpool_limits(2, user_api="blas"):
        with pytest.raises(ParameterError, match="probe"):
            RlfcCodec().encode(lf, EncodeOptions())
        assert _blas_threads(0) == [2]
    assert seen == [[1]]


def test_one_blas_thread_blocks_may_overlap():
    """Two encodes on two threads overlap their blocks (A enters, B enters, A leaves, B leaves):
    BLAS stays on one thread until the last one leaves, then the caller's setting is back."""
    import cv2  # noqa: F401  (as above)
    from threadpoolctl import threadpool_limits

    from formats.parallel import one_blas_thread

    with threadpool_limits(2, user_api="blas"):
        a, b = one_blas_thread(), one_blas_thread()
        a.__enter__()
        b.__enter__()
        assert _blas_threads(0) == [1]
        a.__exit__(None, None, None)
        assert _blas_threads(0) == [1]
        b.__exit__(None, None, None)
        assert _blas_threads(0) == [2]
