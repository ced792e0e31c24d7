"""What runs where the solver work happens: a forked child process or a Dask worker.

Inputs are the validated request as plain JSON data; outputs are a ``Result``
or a problem dict (``service.errors.problem_from_exception``).  Nothing here
touches the web app.
"""

from __future__ import annotations

import contextlib
import os
import threading
import time
from collections.abc import Callable, Iterator
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

from geometry import Toolpath
from geometry import native as geometry_native
from service.convert import (
    Budget,
    Result,
    check_budget,
    columns_of,
    from_schedule,
    machine_fields,
    meta_of,
    ndjson_rows,
    to_problem,
)
from service.errors import problem_from_exception, renamed
from service.resultfile import ResultWriter
from service.schemas import ScheduleRequest
from solvers import native as solvers_native
from solvers import nlp
from solvers.errors import ScheduleError
from solvers.machine import Machine
from solvers.pipeline import STREAM_BLOCK_SAMPLES, Options, SampleBlock, schedule, schedule_stream

#: Seconds between checks that the parent process is still alive.
PARENT_POLL_S = 0.25
#: Samples a job's solver process holds at once (``compute_to_file``): the stream's default, ~34 MB of columns.
JOB_BLOCK_SAMPLES = STREAM_BLOCK_SAMPLES

# the NLP's compiled derivative functions for the default options and the compiled per-point kernels, once here:
# the forkserver imports this module, so every solver process starts with them loaded
nlp.warm_interval_functions(Options().nlp_checkpoints_per_interval)
geometry_native.library()
solvers_native.library()


class Cancelled(Exception):
    """Raised inside the solver (from the progress callback) when the job was cancelled."""


def _problem(request: dict[str, Any], budget: Budget) -> tuple[Toolpath, Machine, Options]:
    req = ScheduleRequest.model_validate(request)
    tp, machine, opts = to_problem(req)
    return tp, machine, check_budget(tp, machine, opts, budget)  # (F-word knots fitted to the budget; its cap)


@contextlib.contextmanager
def _request_names(request: dict[str, Any]) -> Iterator[None]:
    """A solver error raised inside, its machine fields named as the request holds them (``machine_fields``)."""
    try:
        yield
    except ScheduleError as exc:
        named = renamed(exc, machine_fields(ScheduleRequest.model_validate(request).machine))
        if named is exc:
            raise
        raise named from exc


def compute(request: dict[str, Any], budget: Budget, progress: Callable[[float], None] | None = None) -> Result:
    with _request_names(request):
        return from_schedule(schedule(*_problem(request, budget), progress=progress))


def compute_ndjson(
    request: dict[str, Any], budget: Budget, progress: Callable[[float], None] | None = None
) -> Iterator[tuple[str, Any]]:
    """The schedule as NDJSON while it is computed: ("rows", bytes) for each chunk of sample lines as soon as
    its piece has passed the re-check (``solvers.pipeline.schedule_stream``), then ("end", {"summary",
    "diagnostics"}), the same values as ``compute``'s.  Raises what ``compute`` raises."""
    with _request_names(request):
        for item in schedule_stream(*_problem(request, budget), progress=progress):
            if isinstance(item, SampleBlock):
                yield from (("rows", chunk) for chunk in ndjson_rows(columns_of(item.samples)))
            else:
                summary, diagnostics = meta_of(item.summary, item.diagnostics, item.profiles)
                yield "end", {"summary": summary, "diagnostics": diagnostics}


def compute_to_file(
    request: dict[str, Any], budget: Budget, path: Path, progress: Callable[[float], None] | None = None
) -> dict[str, Any]:
    """A job: the schedule written to ``path`` while it is computed (``service.resultfile``), each block of
    samples as it is released (``solvers.pipeline.schedule_stream``, JOB_BLOCK_SAMPLES at most).

    The process holds one block, not the schedule.  A piece with more samples than a block is sampled twice
    (re-checked block by block, then sampled again to be written): a 3 M-sample line took 19.3 s of compute
    against 18.0 s held at once, at a peak RSS of 277 against 885 MB.  Returns the summary.  The file exists
    only once the whole schedule is in it; on a failure its parts are removed and the error raised.  Its
    columns are those of ``save_result(compute(...))`` bit for bit."""
    writer = ResultWriter(path)
    summary: dict[str, Any] | None = None
    try:
        with _request_names(request):
            for item in schedule_stream(*_problem(request, budget), progress=progress,
                                        block_samples=JOB_BLOCK_SAMPLES):
                if isinstance(item, SampleBlock):
                    writer.append(columns_of(item.samples))
                else:  # (the last item)
                    summary, diagnostics = meta_of(item.summary, item.diagnostics, item.profiles)
                    writer.finish(summary, diagnostics)
    except BaseException:
        writer.abort()
        raise
    if summary is None:  # pragma: no cover - schedule_stream always ends with its ScheduleEnd
        raise RuntimeError("the schedule ended without its summary")
    return summary


def run_captured(
    request: dict[str, Any], budget: Budget, progress: Callable[[float], None] | None = None
) -> tuple[str, Any]:
    """("ok", Result) or ("error", problem dict); never raises except Cancelled."""
    try:
        return "ok", compute(request, budget, progress)
    except Cancelled:
        raise
    except BaseException as exc:  # every failure becomes a problem document
        return "error", problem_from_exception(exc)


def _watch_parent() -> None:
    """Exit when the parent (the forkserver, which exits with the service) goes away."""
    parent = os.getppid()

    def loop() -> None:
        while True:
            time.sleep(PARENT_POLL_S)
            if os.getppid() != parent:
                os._exit(3)

    threading.Thread(target=loop, daemon=True, name="parent-watch").start()


def _serve(conn: Connection, work: Callable[[Callable[[float], None]], tuple[str, Any]]) -> None:
    """A forked solver process: ``work(progress)`` at a lower CPU priority (``FEEDSCHED_WORKER_NICE``, default
    5, so that the service's event loop is scheduled first when solvers saturate the cores), its progress
    messages, then its one (kind, payload) message."""
    _watch_parent()
    with contextlib.suppress(OSError, ValueError):
        os.nice(int(os.environ.get("FEEDSCHED_WORKER_NICE", "5")))

    def progress(fraction: float) -> None:
        try:
            conn.send(("progress", float(fraction)))
        except OSError:  # the service stopped listening (cancelled, timed out, shut down): nobody wants the result
            os._exit(4)

    msg = work(progress)
    try:
        conn.send(msg)
        conn.close()
    except OSError:
        os._exit(4)


def child_main(conn: Connection, request: dict[str, Any], budget: Budget) -> None:
    """Entry point of a forked solver process: progress messages, then ("ok", Result) or ("error", problem)."""
    _serve(conn, lambda progress: run_captured(request, budget, progress))


def child_job_main(conn: Connection, request: dict[str, Any], budget: Budget, path: str) -> None:
    """Entry point of a forked solver process running a job: progress messages, then ("ok", summary) once the
    result file ``path`` is complete (``compute_to_file``), or ("error", problem dict)."""

    def work(progress: Callable[[float], None]) -> tuple[str, Any]:
        try:
            return "ok", compute_to_file(request, budget, Path(path), progress)
        except BaseException as exc:  # every failure becomes a problem document
            return "error", problem_from_exception(exc)

    _serve(conn, work)


def child_stream_main(conn: Connection, request: dict[str, Any], budget: Budget) -> None:
    """Entry point of a forked solver process streaming NDJSON: ("rows", bytes) messages as pieces are
    released, then ("end", summary and diagnostics) or ("error", problem dict) once (no progress messages:
    the rows are the progress).  A send blocks while the service's bounded queue is full (a slow client
    slows the solver down instead of filling the service's memory)."""
    _watch_parent()
    with contextlib.suppress(OSError, ValueError):
        os.nice(int(os.environ.get("FEEDSCHED_WORKER_NICE", "5")))

    def send(msg: tuple[str, Any]) -> None:
        try:
            conn.send(msg)
        except OSError:  # the service stopped listening (client gone, cancelled, timed out): stop
            os._exit(4)

    try:
        for msg in compute_ndjson(request, budget):
            send(msg)
    except BaseException as exc:  # every failure becomes a problem document
        send(("error", problem_from_exception(exc)))
    with contextlib.suppress(OSError):
        conn.close()


# --- Dask -----------------------------------------------------------------------
PROGRESS_TOPIC = "feedsched-progress"
CANCELLED_TOPIC = "feedsched-cancelled"


def dask_task(request: dict[str, Any], budget: Budget, job_key: str) -> tuple[str, Any]:
    """Runs on a Dask worker.  Progress goes out as worker events; a set ``{job_key}-cancel`` Event
    stops the solver at its next LP window.  A result travels back as .npz bytes, not a pickle."""
    from distributed import Event, get_worker

    from service.convert import result_bytes

    worker = get_worker()
    cancel = Event(f"{job_key}-cancel")
    last = [0.0]

    def progress(fraction: float) -> None:
        now = time.monotonic()
        if now - last[0] > 0.2 or fraction >= 1.0:
            last[0] = now
            if cancel.is_set():
                raise Cancelled(job_key)
            worker.log_event(PROGRESS_TOPIC, {"job": job_key, "fraction": float(fraction), "pid": os.getpid()})

    try:
        kind, payload = run_captured(request, budget, progress)
    except Cancelled:
        worker.log_event(CANCELLED_TOPIC, {"job": job_key, "pid": os.getpid()})
        return "cancelled", None
    if kind == "ok":
        return "ok", result_bytes(payload)
    return kind, payload
