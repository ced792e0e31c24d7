"""Service settings from environment variables (all optional, embedded defaults)."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path


def _env(name: str, default: str) -> str:
    return os.environ.get(name, default)


@dataclass(frozen=True)
class Settings:
    """Limits and locations.

    Attributes:
        data_dir: job database and result files (FEEDSCHED_DATA_DIR, default ./var).
        max_body_bytes: request bodies above this get 413 (FEEDSCHED_MAX_BODY_BYTES).
        sync_max_control_points: POST /v1/schedule accepts at most this many control points in total
            (FEEDSCHED_SYNC_MAX_CONTROL_POINTS); more get 413 pointing to /v1/jobs.
        sync_max_samples: lower bound of the output sample count above which /v1/schedule answers 413
            (FEEDSCHED_SYNC_MAX_SAMPLES).
        sync_max_intervals / job_max_intervals: LP knot intervals (path length / knot spacing) allowed
            (FEEDSCHED_SYNC_MAX_INTERVALS, FEEDSCHED_JOB_MAX_INTERVALS).
        sync_timeout: seconds of solver work for /v1/schedule; over it the worker is killed and 413 returned
            (FEEDSCHED_SYNC_TIMEOUT).
        job_max_samples: jobs whose sample count lower bound exceeds this fail (FEEDSCHED_JOB_MAX_SAMPLES).
        job_timeout: seconds a job may run before it is killed and failed (FEEDSCHED_JOB_TIMEOUT).
        job_max_attempts: runs of a job interrupted by a restart or a dead worker before it fails
            (FEEDSCHED_JOB_MAX_ATTEMPTS).
        workers: solver processes at once (FEEDSCHED_WORKERS, default the number of cores).
        dask_scheduler: address of a Dask distributed scheduler; when set, solver work goes there
            (FEEDSCHED_DASK_SCHEDULER, e.g. tcp://10.0.0.5:8786).
        max_inflight: synchronous schedules (POST /v1/schedule and /v1/schedule/gcode) being solved or waiting
            for a solver process at once; one more is answered 503 with Retry-After at once
            (FEEDSCHED_MAX_INFLIGHT, default 2 x workers: one solving and one waiting per solver process).
        job_queue_depth: jobs queued or running at once; one more POST /v1/jobs is answered 503
            (FEEDSCHED_JOB_QUEUE_DEPTH, default 32 x workers).
        job_retry_after: Retry-After seconds of a 503 for a full job queue (FEEDSCHED_JOB_RETRY_AFTER, default 10).
    """

    data_dir: Path = field(default_factory=lambda: Path(_env("FEEDSCHED_DATA_DIR", "var")))
    max_body_bytes: int = field(default_factory=lambda: int(_env("FEEDSCHED_MAX_BODY_BYTES", str(16 * 2**20))))
    sync_max_control_points: int = field(
        default_factory=lambda: int(_env("FEEDSCHED_SYNC_MAX_CONTROL_POINTS", "5000")))
    sync_max_samples: int = field(default_factory=lambda: int(_env("FEEDSCHED_SYNC_MAX_SAMPLES", "300000")))
    sync_max_intervals: int = field(default_factory=lambda: int(_env("FEEDSCHED_SYNC_MAX_INTERVALS", "20000")))
    sync_timeout: float = field(default_factory=lambda: float(_env("FEEDSCHED_SYNC_TIMEOUT", "30")))
    job_max_samples: int = field(default_factory=lambda: int(_env("FEEDSCHED_JOB_MAX_SAMPLES", "5000000")))
    job_max_intervals: int = field(default_factory=lambda: int(_env("FEEDSCHED_JOB_MAX_INTERVALS", "1000000")))
    job_timeout: float = field(default_factory=lambda: float(_env("FEEDSCHED_JOB_TIMEOUT", "3600")))
    job_max_attempts: int = field(default_factory=lambda: int(_env("FEEDSCHED_JOB_MAX_ATTEMPTS", "2")))
    workers: int = field(default_factory=lambda: int(_env("FEEDSCHED_WORKERS", str(os.cpu_count() or 1))))
    dask_scheduler: str | None = field(default_factory=lambda: os.environ.get("FEEDSCHED_DASK_SCHEDULER") or None)
    max_inflight: int = field(default_factory=lambda: int(_env("FEEDSCHED_MAX_INFLIGHT", "0")))
    job_queue_depth: int = field(default_factory=lambda: int(_env("FEEDSCHED_JOB_QUEUE_DEPTH", "0")))
    job_retry_after: int = field(default_factory=lambda: int(_env("FEEDSCHED_JOB_RETRY_AFTER", "10")))

    def __post_init__(self) -> None:
        # 0 (the default) derives the limit from the number of solver processes
        workers = max(1, self.workers)
        if self.max_inflight <= 0:
            object.__setattr__(self, "max_inflight", 2 * workers)
        if self.job_queue_depth <= 0:
            object.__setattr__(self, "job_queue_depth", 32 * workers)
        object.__setattr__(self, "job_retry_after", max(1, self.job_retry_after))
