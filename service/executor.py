"""Where solver work runs: an executor interface with two implementations.

- ``LocalProcessExecutor`` (default): one forked process per task from a
  forkserver that has the solver preloaded, at most ``workers`` at once.  A
  timeout or a cancelled awaiting task kills the process (SIGKILL), so the
  solver really stops.  The event loop only waits on a pipe.
- ``DaskExecutor`` (``FEEDSCHED_DASK_SCHEDULER=tcp://host:8786``): tasks go to
  a Dask distributed scheduler; a worker that dies mid-task has its task
  re-run elsewhere by Dask; cancellation sets a Dask Event the task polls
  after every LP window and cancels the future.

``run`` returns a ``Result``; ``run_to_file`` (jobs) writes it to a result file (``service.resultfile``) and
returns its summary: the local executor's solver process writes the file as the samples are released, so
neither process holds the whole result.  Both raise ``WorkFailed`` (problem dict),
``WorkTimeout``, ``WorkerLost`` or ``asyncio.CancelledError``.  ``stream``
yields the result as NDJSON while it is computed: ("rows", bytes) chunks of
sample lines, then ("end", {"summary", "diagnostics"}); it raises the same
errors, also after some rows; closing it early (``aclose``) stops the work.
The local executor streams piece by piece from the solver process; the Dask
executor runs the whole task and then yields its rows (no streaming there).
"""

from __future__ import annotations

import asyncio
import contextlib
import ctypes
import multiprocessing as mp
import secrets
import threading
from collections.abc import AsyncGenerator, Callable
from concurrent.futures import ThreadPoolExecutor
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any, Protocol

from service import resultfile, worker
from service.convert import Budget, Result, ndjson_rows, result_from_bytes, save_result
from service.errors import WorkerLost, WorkFailed, WorkTimeout

Progress = Callable[[float], None]


class Executor(Protocol):
    name: str

    async def start(self) -> None: ...

    async def close(self) -> None: ...

    async def run(self, request: dict[str, Any], budget: Budget, timeout: float,
                  progress: Progress | None = None, tag: str = "") -> Result: ...

    async def run_to_file(self, request: dict[str, Any], budget: Budget, timeout: float, path: Path,
                          progress: Progress | None = None, tag: str = "") -> dict[str, Any]: ...

    def stream(self, request: dict[str, Any], budget: Budget, timeout: float,
               tag: str = "") -> AsyncGenerator[tuple[str, Any], None]: ...

    def running_pids(self) -> dict[str, int]: ...


#: Messages (progress, NDJSON chunks of CHUNK_ROWS lines) buffered per stream between the solver process and
#: the response; when full, the pipe fills and the solver process waits in its send.
STREAM_QUEUE = 8


#: Completed solver tasks between two malloc_trim calls (LocalProcessExecutor).
TRIM_EVERY = 64


def _malloc_trim() -> Callable[[], None]:
    """glibc's malloc_trim(0), or a no-op elsewhere.

    Results arrive unpickled in the pipe-reader threads and are freed on the event loop thread: glibc keeps
    the freed chunks in the reader threads' arenas, and the service's RSS crept up by about 1.5 KB per
    request (0.8 MB/min under load).  Trimming every TRIM_EVERY tasks hands the free pages back."""
    try:
        fn = ctypes.CDLL("libc.so.6").malloc_trim
    except (OSError, AttributeError):
        return lambda: None
    fn.argtypes = [ctypes.c_size_t]

    def trim() -> None:
        fn(0)

    return trim


def _reader(conn: Connection, loop: asyncio.AbstractEventLoop, q: asyncio.Queue[tuple[str, Any]],
            stop: threading.Event | None = None) -> None:
    """Thread: forward every message from the child to the loop; ("lost", None) on EOF.

    With ``stop`` the queue is bounded: the thread waits for room (so the child waits in its send) until
    ``stop`` is set."""
    def post(msg: tuple[str, Any]) -> bool:
        if stop is None:
            with contextlib.suppress(RuntimeError):  # loop closed
                loop.call_soon_threadsafe(q.put_nowait, msg)
            return True
        try:
            fut = asyncio.run_coroutine_threadsafe(q.put(msg), loop)
        except RuntimeError:  # loop closed
            return False
        while True:
            try:
                fut.result(timeout=0.25)
                return True
            except TimeoutError:
                if stop.is_set():
                    fut.cancel()
                    return False
            except BaseException:  # cancelled with the loop
                return False

    try:
        while True:
            msg = conn.recv()
            if not post(msg) or msg[0] not in ("progress", "rows"):
                return
    except (EOFError, OSError):
        post(("lost", None))
    finally:
        conn.close()


class LocalProcessExecutor:
    name = "local"

    def __init__(self, workers: int, preload: tuple[str, ...] = ("service.worker",)) -> None:
        """``preload``: modules the forkserver imports once, so every solver process starts with them (tests
        add a module that instruments the solver)."""
        self.workers = max(1, workers)
        self._ctx = mp.get_context("forkserver")
        self._ctx.set_forkserver_preload(list(preload))
        self._threads = ThreadPoolExecutor(max_workers=2 * self.workers + 2, thread_name_prefix="feedsched-pipe")
        self._sem: asyncio.Semaphore | None = None
        self._pids: dict[str, int] = {}
        self._lock = threading.Lock()
        self._done = 0
        self._trim = _malloc_trim()

    async def start(self) -> None:
        self._sem = asyncio.Semaphore(self.workers)
        # start the forkserver now (imports numpy/scipy/HiGHS once) rather than on the first request
        loop = asyncio.get_running_loop()
        await loop.run_in_executor(self._threads, self._warm)

    def _warm(self) -> None:
        p = self._ctx.Process(target=_noop, daemon=True)
        p.start()
        p.join()

    async def close(self) -> None:
        with self._lock:
            pids = list(self._pids.values())
        for pid in pids:
            _kill(pid)
        self._threads.shutdown(wait=False, cancel_futures=True)

    def running_pids(self) -> dict[str, int]:
        with self._lock:
            return dict(self._pids)

    async def run(self, request: dict[str, Any], budget: Budget, timeout: float,
                  progress: Progress | None = None, tag: str = "") -> Result:
        res = await self._run_limited(request, budget, timeout, progress, tag)
        assert isinstance(res, Result)
        return res

    async def run_to_file(self, request: dict[str, Any], budget: Budget, timeout: float, path: Path,
                          progress: Progress | None = None, tag: str = "") -> dict[str, Any]:
        try:
            summary = await self._run_limited(request, budget, timeout, progress, tag, path)
        except BaseException:
            # (a killed process leaves its parts; one that failed removed them itself)
            await asyncio.shield(asyncio.to_thread(resultfile.remove_partial, path))
            raise
        assert isinstance(summary, dict)
        return summary

    async def _run_limited(self, request: dict[str, Any], budget: Budget, timeout: float,
                           progress: Progress | None, tag: str, path: Path | None = None) -> Any:
        """``_run_one`` once one of the ``workers`` slots is free."""
        if self._sem is None:
            await self.start()
        assert self._sem is not None
        async with self._sem:
            return await self._run_one(request, budget, timeout, progress, tag or secrets.token_hex(8), path)

    async def _run_one(self, request: dict[str, Any], budget: Budget, timeout: float,
                       progress: Progress | None, tag: str, path: Path | None = None) -> Any:
        """The task in a solver process: ``worker.child_main`` (a Result), or with ``path``
        ``worker.child_job_main`` (the summary; the result in the file)."""
        loop = asyncio.get_running_loop()
        recv_end, send_end = self._ctx.Pipe(duplex=False)
        target, args = ((worker.child_main, (send_end, request, budget)) if path is None
                        else (worker.child_job_main, (send_end, request, budget, str(path))))
        proc = self._ctx.Process(target=target, args=args, daemon=True, name=f"feedsched-{tag}")
        await loop.run_in_executor(self._threads, proc.start)
        send_end.close()
        with self._lock:
            self._pids[tag] = proc.pid or -1
        q: asyncio.Queue[tuple[str, Any]] = asyncio.Queue()
        self._threads.submit(_reader, recv_end, loop, q)
        try:
            try:
                async with asyncio.timeout(timeout):
                    while True:
                        kind, payload = await q.get()
                        if kind != "progress":
                            break
                        if progress is not None:
                            progress(payload)
            except TimeoutError:
                raise WorkTimeout(f"solver work took longer than {timeout:g} s") from None
            if kind == "ok":
                return payload
            if kind == "error":
                raise WorkFailed(payload)
            await loop.run_in_executor(self._threads, proc.join, 5.0)
            raise WorkerLost(f"solver process {proc.pid} ended without a result (exit code {proc.exitcode})")
        finally:
            if proc.is_alive():
                proc.kill()
            await asyncio.shield(loop.run_in_executor(self._threads, proc.join, 5.0))
            with self._lock:
                self._pids.pop(tag, None)
            self._done += 1
            if self._done % TRIM_EVERY == 0:
                self._threads.submit(self._trim)


    async def stream(self, request: dict[str, Any], budget: Budget, timeout: float,
                     tag: str = "") -> AsyncGenerator[tuple[str, Any], None]:
        """NDJSON chunks as the solver process releases them (``worker.child_stream_main``).

        ``timeout`` bounds the whole stream.  The process is killed when the stream ends early: an error,
        the timeout, or ``aclose`` (the client went away).  Cleanup never awaits (it may run in a
        cancelled task): the kill is immediate, the process is reaped by a pipe thread."""
        if self._sem is None:
            await self.start()
        assert self._sem is not None
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timeout
        tag = tag or secrets.token_hex(8)
        async with self._sem:
            recv_end, send_end = self._ctx.Pipe(duplex=False)
            proc = self._ctx.Process(target=worker.child_stream_main, args=(send_end, request, budget),
                                     daemon=True, name=f"feedsched-{tag}")
            await loop.run_in_executor(self._threads, proc.start)
            send_end.close()
            with self._lock:
                self._pids[tag] = proc.pid or -1
            q: asyncio.Queue[tuple[str, Any]] = asyncio.Queue(maxsize=STREAM_QUEUE)
            stop = threading.Event()
            self._threads.submit(_reader, recv_end, loop, q, stop)
            try:
                while True:
                    try:
                        async with asyncio.timeout_at(deadline):
                            kind, payload = await q.get()
                    except TimeoutError:
                        raise WorkTimeout(f"solver work took longer than {timeout:g} s") from None
                    if kind == "progress":
                        continue
                    if kind == "rows":
                        yield kind, payload
                        continue
                    if kind == "end":
                        yield kind, payload
                        return
                    if kind == "error":
                        raise WorkFailed(payload)
                    await loop.run_in_executor(self._threads, proc.join, 5.0)
                    raise WorkerLost(f"solver process {proc.pid} ended without a result (exit code {proc.exitcode})")
            finally:
                stop.set()
                if proc.is_alive():
                    proc.kill()
                self._threads.submit(proc.join, 5.0)
                with self._lock:
                    self._pids.pop(tag, None)
                self._done += 1
                if self._done % TRIM_EVERY == 0:
                    self._threads.submit(self._trim)


def _noop() -> None:
    pass


def _kill(pid: int) -> None:
    import os
    import signal

    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.kill(pid, signal.SIGKILL)


class DaskExecutor:
    name = "dask"

    def __init__(self, address: str) -> None:
        self.address = address
        self._client: Any = None
        self._progress: dict[str, Progress] = {}
        self._pids: dict[str, int] = {}
        self._tags: dict[str, str] = {}

    async def start(self) -> None:
        from distributed import Client

        self._client = await Client(self.address, asynchronous=True)
        self._client.subscribe_topic(worker.PROGRESS_TOPIC, self._on_event)

    def _on_event(self, event: tuple[float, dict[str, Any]]) -> None:
        msg = event[1]
        key = str(msg.get("job", ""))
        cb = self._progress.get(key)
        tag = self._tags.get(key)
        if tag is not None:
            self._pids[tag] = int(msg.get("pid", -1))
        if cb is not None:
            cb(float(msg["fraction"]))

    async def close(self) -> None:
        if self._client is not None:
            await self._client.close()

    def running_pids(self) -> dict[str, int]:
        return dict(self._pids)

    async def run(self, request: dict[str, Any], budget: Budget, timeout: float,
                  progress: Progress | None = None, tag: str = "") -> Result:
        from distributed import Event

        if self._client is None:
            await self.start()
        key = f"feedsched-{tag or 'sync'}-{secrets.token_hex(6)}"
        if progress is not None:
            self._progress[key] = progress
        self._tags[key] = tag
        fut = self._client.submit(worker.dask_task, request, budget, key, key=key, pure=False)
        try:
            try:
                async with asyncio.timeout(timeout):
                    kind, payload = await fut
            except TimeoutError:
                raise WorkTimeout(f"solver work took longer than {timeout:g} s") from None
            except Exception as exc:  # KilledWorker after too many worker deaths, comm errors
                if isinstance(exc, asyncio.CancelledError):
                    raise
                raise WorkerLost(f"Dask could not run the task: {type(exc).__name__}: {exc}") from None
            if kind == "ok":
                return result_from_bytes(payload)
            if kind == "error":
                raise WorkFailed(payload)
            raise asyncio.CancelledError()
        except BaseException:
            if not fut.done():
                with contextlib.suppress(Exception):
                    await Event(f"{key}-cancel", client=self._client).set()
                with contextlib.suppress(Exception):
                    await fut.cancel()
            raise
        finally:
            self._progress.pop(key, None)
            self._pids.pop(self._tags.pop(key, ""), None)


    async def run_to_file(self, request: dict[str, Any], budget: Budget, timeout: float, path: Path,
                          progress: Progress | None = None, tag: str = "") -> dict[str, Any]:
        """``run``, then the result written to ``path`` here (a Dask task returns its result whole)."""
        res = await self.run(request, budget, timeout, progress, tag)
        await asyncio.to_thread(save_result, res, path)
        return res.summary

    async def stream(self, request: dict[str, Any], budget: Budget, timeout: float,
                     tag: str = "") -> AsyncGenerator[tuple[str, Any], None]:
        """The whole task on the cluster, then its rows (Dask returns a task's result at its end only)."""
        res = await self.run(request, budget, timeout, tag=tag)
        chunks = ndjson_rows(res.columns)
        while (chunk := await asyncio.to_thread(next, chunks, None)) is not None:
            yield "rows", chunk
        yield "end", {"summary": res.summary, "diagnostics": res.diagnostics}


def make_executor(workers: int, dask_scheduler: str | None) -> Executor:
    if dask_scheduler:
        return DaskExecutor(dask_scheduler)
    return LocalProcessExecutor(workers)
