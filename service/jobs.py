"""Asynchronous jobs: queue, run through the executor, persist, recover after a restart."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from typing import Any

from service.config import Settings
from service.convert import Budget
from service.errors import WorkerLost, problem_from_exception
from service.executor import Executor
from service.limits import busy
from service.store import ACTIVE, Job, JobStore

log = logging.getLogger("feedsched.jobs")
#: Seconds between progress writes to the database per job (the latest value is always served from memory).
PROGRESS_WRITE_S = 0.5


class JobManager:
    def __init__(self, store: JobStore, executor: Executor, settings: Settings) -> None:
        self.store = store
        self.executor = executor
        self.settings = settings
        self.budget = Budget(settings.job_max_samples, settings.job_max_intervals, where="a job")
        self._tasks: dict[str, asyncio.Task[None]] = {}
        self._progress: dict[str, float] = {}
        self._written: dict[str, float] = {}
        self._sem = asyncio.Semaphore(max(1, settings.workers))
        self._closing = False
        self.refused = 0

    async def start(self) -> None:
        """Re-run jobs a previous process left queued or running (or fail them after too many attempts)."""
        for job in self.store.active():
            if job.status == "running" and job.attempts >= self.settings.job_max_attempts:
                self.store.finish(job.id, "failed", error=_interrupted(job))
                continue
            if job.status == "running":
                log.info("re-running job %s interrupted by a restart (attempt %d)", job.id, job.attempts + 1)
                self.store.requeue(job.id)
            self._spawn(job.id)

    async def close(self) -> None:
        """Stop without deciding the fate of running jobs: they stay 'running' and are re-run on start."""
        self._closing = True
        tasks = list(self._tasks.values())
        for t in tasks:
            t.cancel()
        for t in tasks:
            with contextlib.suppress(BaseException):
                await t

    def active_count(self) -> int:
        """Jobs queued or running in this process."""
        return len(self._tasks)

    def submit(self, request: dict[str, Any], idempotency_key: str | None) -> tuple[Job, bool]:
        """Create and start a job (or return the job of a known idempotency key); 503 when the queue is full."""
        if idempotency_key is not None:
            old = self.store.by_key(idempotency_key)
            if old is not None:
                return old, False
        n = self.active_count()
        if n >= self.settings.job_queue_depth:
            self.refused += 1
            ra = self.settings.job_retry_after
            raise busy(f"{n} jobs queued or running, the queue holds {self.settings.job_queue_depth}; "
                       f"retry after {ra} s", value=n,
                       rule=f"at most {self.settings.job_queue_depth} jobs queued or running "
                       "(FEEDSCHED_JOB_QUEUE_DEPTH)", retry_after=ra)
        job, created = self.store.create(request, idempotency_key)
        if created:
            self._spawn(job.id)
        return job, created

    def progress(self, job: Job) -> float:
        return self._progress.get(job.id, job.progress) if job.status == "running" else job.progress

    async def cancel(self, job_id: str) -> bool:
        """Mark cancelled and kill the work.  False if the job had already finished."""
        done = self._finish(job_id, "cancelled")
        task = self._tasks.get(job_id)
        if task is not None:
            task.cancel()
            with contextlib.suppress(BaseException):
                await task
        return done

    def _finish(self, job_id: str, status: str, **fields: Any) -> bool:
        """``store.finish`` with the job's latest progress written first: the stored value is written at most every
        PROGRESS_WRITE_S, and a cancelled job read 0.025 where its last poll had read 0.275."""
        fraction = self._progress.get(job_id)
        if fraction is not None:
            self.store.set_progress(job_id, fraction)
        return self.store.finish(job_id, status, **fields)

    def _spawn(self, job_id: str) -> None:
        task = asyncio.create_task(self._run(job_id), name=f"job-{job_id}")
        self._tasks[job_id] = task
        task.add_done_callback(lambda _: self._tasks.pop(job_id, None))

    def _on_progress(self, job_id: str, fraction: float) -> None:
        self._progress[job_id] = fraction
        now = time.monotonic()
        if now - self._written.get(job_id, 0.0) >= PROGRESS_WRITE_S:
            self._written[job_id] = now
            self.store.set_progress(job_id, fraction)

    async def _run(self, job_id: str) -> None:
        try:
            async with self._sem:
                while True:
                    job = self.store.get(job_id)
                    if job is None or job.status not in ACTIVE:
                        return
                    self.store.mark_running(job_id)
                    path = self.store.result_path(job_id)
                    try:
                        # (the solver process writes the result file as it goes: neither process holds it)
                        summary = await self.executor.run_to_file(
                            job.request, self.budget, self.settings.job_timeout, path,
                            lambda f: self._on_progress(job_id, f), tag=job_id)
                    except asyncio.CancelledError:
                        now = self.store.get(job_id)
                        if now is None or now.status != "running":  # (not a shutdown, which re-runs it)
                            path.unlink(missing_ok=True)  # (the process may have finished the file)
                        raise
                    except WorkerLost as exc:
                        path.unlink(missing_ok=True)
                        if job.attempts + 1 < self.settings.job_max_attempts:
                            log.warning("job %s: %s; re-running", job_id, exc)
                            self.store.requeue(job_id)
                            continue
                        self._finish(job_id, "failed", error=problem_from_exception(exc))
                        return
                    except Exception as exc:
                        path.unlink(missing_ok=True)
                        self._finish(job_id, "failed", error=problem_from_exception(exc))
                        return
                    if not self.store.finish(job_id, "succeeded", summary=summary):
                        path.unlink(missing_ok=True)  # cancelled while it was written
                    return
        finally:
            self._progress.pop(job_id, None)
            self._written.pop(job_id, None)


def _interrupted(job: Job) -> dict[str, Any]:
    return {
        "type": "urn:feedsched:problem:interrupted", "title": "Interrupted", "status": 503,
        "detail": f"the service stopped during each of the {job.attempts} attempts to run this job",
        "errors": [{"field": None, "pointer": None, "value": job.attempts,
                    "rule": "a job interrupted by restarts is re-run at most FEEDSCHED_JOB_MAX_ATTEMPTS times"}],
    }
