"""Embedded job store: SQLite (stdlib) for job records, one .npz file per result.

Layout under the data dir::

    jobs.sqlite3          job records (request JSON, status, timings, error problem JSON)
    results/<id>.npz      float64 columns + JSON metadata (never pickle)

Job ids come from ``secrets.token_urlsafe``; any id from a URL is checked
against ``ID_PATTERN`` before it is used in SQL or in a file name.
"""

from __future__ import annotations

import json
import re
import secrets
import sqlite3
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

ID_PATTERN = re.compile(r"^[A-Za-z0-9_-]{16,64}$")
ACTIVE = ("queued", "running")

_SCHEMA = """
CREATE TABLE IF NOT EXISTS jobs (
    id TEXT PRIMARY KEY,
    idempotency_key TEXT UNIQUE,
    status TEXT NOT NULL,
    request TEXT NOT NULL,
    progress REAL NOT NULL DEFAULT 0,
    attempts INTEGER NOT NULL DEFAULT 0,
    created REAL NOT NULL,
    started REAL,
    finished REAL,
    error TEXT,
    summary TEXT
);
CREATE INDEX IF NOT EXISTS jobs_status ON jobs(status);
"""


@dataclass(frozen=True)
class Job:
    id: str
    idempotency_key: str | None
    status: str
    request: dict[str, Any]
    progress: float
    attempts: int
    created: float
    started: float | None
    finished: float | None
    error: dict[str, Any] | None
    summary: dict[str, Any] | None


def valid_id(job_id: str) -> bool:
    return bool(ID_PATTERN.fullmatch(job_id))


class JobStore:
    def __init__(self, data_dir: Path) -> None:
        self.dir = Path(data_dir)
        self.results = self.dir / "results"
        self.results.mkdir(parents=True, exist_ok=True)
        self._db = sqlite3.connect(self.dir / "jobs.sqlite3", check_same_thread=False, isolation_level=None)
        self._db.execute("PRAGMA journal_mode=WAL")
        self._db.execute("PRAGMA synchronous=NORMAL")
        self._db.executescript(_SCHEMA)
        self._lock = threading.Lock()

    def close(self) -> None:
        with self._lock:
            self._db.close()

    def _row(self, r: tuple[Any, ...] | None) -> Job | None:
        if r is None:
            return None
        return Job(id=r[0], idempotency_key=r[1], status=r[2], request=json.loads(r[3]), progress=r[4],
                   attempts=r[5], created=r[6], started=r[7], finished=r[8],
                   error=json.loads(r[9]) if r[9] else None, summary=json.loads(r[10]) if r[10] else None)

    def create(self, request: dict[str, Any], idempotency_key: str | None) -> tuple[Job, bool]:
        """Insert a queued job; with a known idempotency key return the existing one.  (job, created?)"""
        with self._lock:
            if idempotency_key is not None:
                old = self._get(self._db.execute("SELECT * FROM jobs WHERE idempotency_key=?", (idempotency_key,)))
                if old is not None:
                    return old, False
            job_id = secrets.token_urlsafe(18)
            self._db.execute(
                "INSERT INTO jobs (id, idempotency_key, status, request, created) VALUES (?, ?, 'queued', ?, ?)",
                (job_id, idempotency_key, json.dumps(request), time.time()),
            )
            job = self._get(self._db.execute("SELECT * FROM jobs WHERE id=?", (job_id,)))
        assert job is not None
        return job, True

    def by_key(self, idempotency_key: str) -> Job | None:
        with self._lock:
            return self._get(self._db.execute("SELECT * FROM jobs WHERE idempotency_key=?", (idempotency_key,)))

    def _get(self, cur: sqlite3.Cursor) -> Job | None:
        return self._row(cur.fetchone())

    def get(self, job_id: str) -> Job | None:
        if not valid_id(job_id):
            return None
        with self._lock:
            return self._get(self._db.execute("SELECT * FROM jobs WHERE id=?", (job_id,)))

    def active(self) -> list[Job]:
        with self._lock:
            rows = self._db.execute("SELECT * FROM jobs WHERE status IN ('queued', 'running') ORDER BY created")
            return [j for j in (self._row(r) for r in rows.fetchall()) if j is not None]

    def mark_running(self, job_id: str) -> None:
        with self._lock:
            self._db.execute("UPDATE jobs SET status='running', started=?, attempts=attempts+1, progress=0 "
                             "WHERE id=?", (time.time(), job_id))

    def set_progress(self, job_id: str, fraction: float) -> None:
        with self._lock:
            self._db.execute("UPDATE jobs SET progress=? WHERE id=? AND status='running'", (fraction, job_id))

    def requeue(self, job_id: str) -> None:
        with self._lock:
            self._db.execute("UPDATE jobs SET status='queued', progress=0 WHERE id=?", (job_id,))

    def finish(self, job_id: str, status: str, *, error: dict[str, Any] | None = None,
               summary: dict[str, Any] | None = None) -> bool:
        """Set a final status unless the job already has one (a cancel wins over a late result)."""
        with self._lock:
            cur = self._db.execute(
                "UPDATE jobs SET status=?, finished=?, error=?, summary=?, progress=CASE WHEN ?='succeeded' "
                "THEN 1 ELSE progress END WHERE id=? AND status IN ('queued', 'running')",
                (status, time.time(), json.dumps(error) if error else None, json.dumps(summary) if summary else None,
                 status, job_id),
            )
            return cur.rowcount == 1

    def result_path(self, job_id: str) -> Path:
        if not valid_id(job_id):
            raise ValueError("invalid job id")
        return self.results / f"{job_id}.npz"
