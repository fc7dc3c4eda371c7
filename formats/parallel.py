"""Where an encode's independent tasks run: in this process, on a local process pool
(``--workers N``), or on a dask.distributed cluster (``--scheduler ADDRESS``, or a
``distributed.Client`` passed from Python).

A codec asks a :class:`Runner` for two things:

* ``share(obj)``: an object many tasks read (the encoder's parameters, the decoded key views
  of one rate-control pass, the entropy model). It is sent to each worker once, not once per
  task: the pool writes it to a temporary file that workers load (and keep, a few at a time);
  dask scatters it to every worker.
* ``map(fn, arglists)``: ``[fn(*args) for args in arglists]`` with shared handles resolved,
  results in the order given whatever order they finish in.
* ``map_threaded(fn, arglists)``: the same for tasks that release the GIL (OpenCV, numpy on
  large arrays); the serial runner runs them on a few threads of this process (one OpenCV
  thread and one BLAS thread each), the others as ``map``.

Tasks must be deterministic functions of their arguments: the file an encode writes is then the
same, byte for byte, whatever runs it (same platform and numpy build; floating-point results of
a different CPU or numpy may differ; numpy's BLAS runs on one thread during an encode,
:func:`one_blas_thread`, so a GEMM's floats do not depend on the machine's cores). Workers run
one thread each: the pool is the parallelism. The pool spawns fresh interpreters, so a script
that asks for workers must keep its top level under ``if __name__ == "__main__":`` (as every
multiprocessing program does). Failures come back as the task's own exception (an
:class:`LfcError` stays one); a worker that dies (out of memory, killed) is a
:class:`WorkerError`.
"""
from __future__ import annotations

import contextlib
import os
import pickle
import tempfile
import threading
import uuid
from collections import OrderedDict
from typing import Any, Callable, Sequence

from .errors import ParameterError, WorkerError

MAX_WORKERS = 256
CONNECT_TIMEOUT = "20s"          # how long a --scheduler address is tried
#: threads of :meth:`Runner.map_threaded` in this process: the cores this process may use, at
#: most 4 (each task holds a view's temporaries: hci_antinous's encode peaks at 480 MiB on two
#: threads against 438 MiB one after another). OpenCV and numpy release the GIL in the encoder's
#: tasks, and one OpenCV thread per task spends about half the CPU of OpenCV's own pool splitting
#: each small warp (BENCHMARKS.md)
LOCAL_THREADS = min(len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1), 4)


@contextlib.contextmanager
def one_cv2_thread():
    """OpenCV's thread pool off (one thread) inside the block, restored after it."""
    import cv2

    n = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        yield
    finally:
        cv2.setNumThreads(n)


_BLAS: dict = {"depth": 0, "limiter": None}
_BLAS_LOCK = threading.Lock()


@contextlib.contextmanager
def one_blas_thread():
    """numpy's BLAS (OpenBLAS, the GEMMs of the encoder's quantizer and transforms) on one thread
    inside the block, restored after it: our own threads are the parallelism there. Left alone,
    each of two task threads' GEMMs wakes the BLAS library's own threads, which spin while they
    wait: on the 2-core box a default encode took 1.2-1.9x the CPU and 1.1-1.7x the wall time
    (BENCHMARKS.md, "Encode cost"). One thread also makes a GEMM's floats, and so the file, the
    same whatever the machine's cores. The setting is process-wide (threadpoolctl, on every BLAS
    library loaded when the outermost block starts): blocks may nest and overlap across threads
    (two encodes on two threads); the first to enter sets it, the last to leave restores the
    caller's."""
    with _BLAS_LOCK:
        if _BLAS["depth"] == 0:       # the libraries loaded now (scipy's OpenBLAS may have come since the
            import cv2  # noqa: F401  # last block); OpenCV brings one of its own: loaded before they are listed
            from threadpoolctl import ThreadpoolController

            _BLAS["limiter"] = ThreadpoolController().limit(limits=1, user_api="blas")     # (~0.4 ms)
        _BLAS["depth"] += 1
    try:
        yield
    finally:
        with _BLAS_LOCK:
            _BLAS["depth"] -= 1
            if _BLAS["depth"] == 0:
                _BLAS["limiter"].restore_original_limits()
                _BLAS["limiter"] = None


class Runner:
    """Runs tasks in this process, one after another (``--workers 1``, the default)."""

    workers = 1
    kind = "serial"

    def share(self, obj: Any) -> Any:
        return obj

    def scatter(self, objs: Sequence[Any]) -> list:
        """Handles of objects each read by one task (a view's pixels): sent once, where the
        task that reads them runs when the runner can arrange it."""
        return list(objs)

    def map(self, fn: Callable, arglists: Sequence[tuple], done: Callable[[int], None] | None = None,
            take: Callable[[int, Any], Any] | None = None) -> list:
        """``[fn(*args) for args in arglists]``; ``done(1)`` after each task; ``take(i, result)``,
        where given, is called as each result arrives and its value is kept instead (so that
        a caller can move a large result where it belongs before the next one arrives)."""
        out = []
        for i, args in enumerate(arglists):
            r = fn(*args)
            out.append(take(i, r) if take else r)
            if done:
                done(1)
        return out

    def map_threaded(self, fn: Callable, arglists: Sequence[tuple], done: Callable[[int], None] | None = None,
                     threads: int | None = None, take: Callable[[int, Any], Any] | None = None) -> list:
        """:meth:`map` for tasks that release the GIL (OpenCV, large numpy arrays): in this
        process, on a pool of ``threads`` (default LOCAL_THREADS) threads with one OpenCV and one
        BLAS thread each; results in order, the same values as :meth:`map`. Other runners: their
        own map."""
        n = LOCAL_THREADS if threads is None else threads
        if self.kind != "serial" or len(arglists) < 2:
            return self.map(fn, arglists, done, take)
        with one_cv2_thread():
            if n <= 1:
                return self.map(fn, arglists, done, take)
            from concurrent.futures import ThreadPoolExecutor

            out = []
            with one_blas_thread(), ThreadPoolExecutor(n) as ex:
                for i, r in enumerate(ex.map(lambda a: fn(*a), arglists)):
                    out.append(take(i, r) if take else r)
                    if done:
                        done(1)
            return out

    def map_dag(self, fn: Callable, arglists: Sequence[tuple], deps: Sequence[Sequence[int]],
                finish: Callable[[int, Any], Any] | None = None, threads: int | None = None) -> list:
        """``[fn(*args) for args in arglists]`` where task i may start only once the tasks
        ``deps[i]`` (indices below i) have finished, on ``threads`` threads of this process
        (default LOCAL_THREADS; one OpenCV and one BLAS thread each), always the lowest-indexed
        ready task first (put the tasks others wait on first). ``finish(i, result)``, where given, runs in
        the calling thread as each task finishes and before any task that waits on it starts
        (it may write what those tasks read); its value is kept. With one thread: in index order.
        Tasks must not depend on what runs beside them: the results are then the same whatever
        the threads."""
        n = len(arglists)
        t = LOCAL_THREADS if threads is None else threads
        if any(j >= i or j < 0 for i, d in enumerate(deps) for j in d):
            raise ValueError("map_dag: a task may wait only on tasks before it")
        if t <= 1 or n < 2:
            out = []
            with one_cv2_thread():
                for i, args in enumerate(arglists):
                    r = fn(*args)
                    out.append(finish(i, r) if finish else r)
            return out
        import heapq
        from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait

        waiting = [len(set(d)) for d in deps]
        children: list = [[] for _ in range(n)]
        for i, d in enumerate(deps):
            for j in set(d):
                children[j].append(i)
        ready = [i for i in range(n) if waiting[i] == 0]
        heapq.heapify(ready)
        out: list = [None] * n
        with one_cv2_thread(), one_blas_thread(), ThreadPoolExecutor(t) as ex:
            running: dict = {}
            try:
                while ready or running:
                    while ready and len(running) < t:
                        i = heapq.heappop(ready)
                        running[ex.submit(fn, *arglists[i])] = i
                    fin, _ = wait(running, return_when=FIRST_COMPLETED)
                    for f in sorted(fin, key=running.get):
                        i = running.pop(f)
                        r = f.result()
                        out[i] = finish(i, r) if finish else r
                        for c in children[i]:
                            waiting[c] -= 1
                            if waiting[c] == 0:
                                heapq.heappush(ready, c)
            except BaseException:
                for f in running:
                    f.cancel()
                raise
        return out

    def close(self) -> None:
        pass

    def describe(self) -> dict:
        return {"runner": self.kind, "workers": self.workers}

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


# -- local process pool -----------------------------------------------------------------------
class _Shared:
    """A handle to an object pickled into a file (loaded by workers, cached per process)."""

    __slots__ = ("path",)

    def __init__(self, path: str):
        self.path = path


_CACHE: "OrderedDict[str, Any]" = OrderedDict()
_CACHE_ENTRIES = 3          # a codec's task reads its shared parameters, one pass's data and model


def _resolve(a):
    if isinstance(a, _Shared):
        obj = _CACHE.get(a.path)
        if obj is None:
            with open(a.path, "rb") as f:
                obj = pickle.load(f)
            _CACHE[a.path] = obj
            while len(_CACHE) > _CACHE_ENTRIES:
                _CACHE.popitem(last=False)
        else:
            _CACHE.move_to_end(a.path)
        return obj
    return a


def _call(fn, args):
    return fn(*[_resolve(a) for a in args])


def _init_worker():
    """A pool worker's start: one malloc arena (:mod:`formats.heap`). Its threads are already
    limited to one by the environment it starts with (``OMP_NUM_THREADS``, which torch also
    reads when a task imports it; importing torch here cost each worker ~185 MiB)."""
    from .heap import limit_arenas

    limit_arenas(1)


class PoolRunner(Runner):
    """A local pool of ``workers`` processes (spawned: no state leaks in from the parent)."""

    kind = "pool"

    def __init__(self, workers: int):
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        self.workers = workers
        self._dir = tempfile.TemporaryDirectory(prefix="lfcodec-share-")
        names = ("OMP_NUM_THREADS", "OPENCV_FOR_THREADS_NUM")
        old = {k: os.environ.get(k) for k in names}
        os.environ.update({k: "1" for k in names})     # inherited by the spawned workers
        try:
            self._pool = ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn"),
                                             initializer=_init_worker)
            self._pool.submit(int, 0).result()       # start the workers while the variable is set
        except Exception as e:
            self._dir.cleanup()
            raise WorkerError(f"the worker processes did not start ({type(e).__name__}); a script that asks for "
                              "workers must guard its top level with if __name__ == '__main__':") from None
        finally:
            for k, v in old.items():
                if v is None:
                    os.environ.pop(k, None)
                else:
                    os.environ[k] = v

    def share(self, obj):
        path = os.path.join(self._dir.name, uuid.uuid4().hex)
        with open(path, "wb") as f:
            pickle.dump(obj, f, protocol=pickle.HIGHEST_PROTOCOL)
        return _Shared(path)

    def map(self, fn, arglists, done=None, take=None):
        from concurrent.futures import as_completed
        from concurrent.futures.process import BrokenProcessPool

        futs = [self._pool.submit(_call, fn, tuple(args)) for args in arglists]
        index = {f: i for i, f in enumerate(futs)}
        out: list = [None] * len(futs)
        try:
            for f in as_completed(futs):
                i = index[f]
                out[i] = take(i, f.result()) if take else f.result()
                if done:
                    done(1)
        except BrokenProcessPool as e:
            raise WorkerError(f"a worker process died ({e}); try fewer --workers or a smaller light field") from None
        finally:
            for f in futs:
                f.cancel()
        return out

    def close(self):
        self._pool.shutdown(wait=True, cancel_futures=True)
        self._dir.cleanup()


# -- dask.distributed ---------------------------------------------------------------------------
class DaskRunner(Runner):
    """Tasks on a dask.distributed cluster: ``client`` is a Client, or a scheduler address
    (``tcp://host:8786``) this runner connects to and closes."""

    kind = "dask"

    def __init__(self, client):
        try:
            from distributed import Client
        except ImportError:
            raise ParameterError("--scheduler needs dask.distributed: pip install 'lfcodec[dask]'") from None
        self._own = not isinstance(client, Client)
        if self._own:
            try:
                client = Client(client, timeout=CONNECT_TIMEOUT, set_as_default=False)
            except (OSError, TimeoutError, ValueError) as e:
                raise WorkerError(f"cannot reach the dask scheduler {client}: {e}") from None
        self.client = client
        self.workers = max(1, sum(w.get("nthreads", 1) for w in client.scheduler_info()["workers"].values()))

    def share(self, obj):
        return self.client.scatter(obj, broadcast=True, hash=False)

    def scatter(self, objs):
        return self.client.scatter(list(objs), hash=False)

    def map(self, fn, arglists, done=None, take=None):
        from distributed import as_completed

        futs = [self.client.submit(fn, *args, pure=False) for args in arglists]
        index = {f.key: i for i, f in enumerate(futs)}
        out: list = [None] * len(futs)
        try:
            for f in as_completed(futs, loop=self.client.loop):      # (this client's loop: it may not be the default)
                i = index[f.key]
                out[i] = take(i, f.result()) if take else f.result()
                if done:
                    done(1)
        finally:
            for f in futs:
                f.release()
        return out

    def close(self):
        if self._own:
            self.client.close()

    def describe(self):
        return {"runner": self.kind, "workers": self.workers, "scheduler": self.client.scheduler.address}


def check_runner(workers: int = 1, scheduler=None) -> None:
    """Raise :class:`ParameterError` for a worker count or scheduler that cannot be used."""
    if not isinstance(workers, int) or isinstance(workers, bool) or not 1 <= workers <= MAX_WORKERS:
        raise ParameterError(f"--workers must be an integer within 1..{MAX_WORKERS}, got {workers!r}")
    if scheduler is not None:
        if workers != 1:
            raise ParameterError("give --workers or --scheduler, not both (the cluster has its own workers)")
        if isinstance(scheduler, str) and ("://" not in scheduler and ":" not in scheduler or " " in scheduler):
            raise ParameterError(f"--scheduler must be an address such as tcp://host:8786, got {scheduler!r}")


def make_runner(workers: int = 1, scheduler=None) -> Runner:
    """The runner for ``--workers N`` / ``--scheduler ADDRESS`` (or a distributed Client).

    Raises:
        ParameterError: workers outside 1..256, or both a pool and a scheduler asked for.
        WorkerError: the scheduler cannot be reached.
    """
    check_runner(workers, scheduler)
    if scheduler is not None:
        return DaskRunner(scheduler)
    return PoolRunner(workers) if workers > 1 else Runner()


__all__ = ["Runner", "PoolRunner", "DaskRunner", "WorkerError", "check_runner", "make_runner"]
