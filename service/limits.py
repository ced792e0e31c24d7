"""Admission control: bounded in-flight solver work, answered 503 + Retry-After beyond the bound.

Nothing here waits: a request is admitted or refused on the spot (the check and the count change happen
without an ``await`` between them, so the event loop makes them atomic).
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from service.errors import ServiceError

#: Bounds of a Retry-After (seconds) computed from recent solve times.
RETRY_AFTER_MIN_S = 1
RETRY_AFTER_MAX_S = 60


def busy(detail: str, *, value: Any, rule: str, retry_after: int) -> ServiceError:
    """503 problem+json with a Retry-After header."""
    return ServiceError(503, "busy", "Service busy", detail, field=None, value=value, rule=rule,
                        headers={"Retry-After": str(retry_after)}, retry_after_s=retry_after)


class Gate:
    """At most ``limit`` holders at once; ``enter`` raises 503 beyond that.

    Retry-After is the exponential moving average of how long a holder stayed (rounded up, 1-60 s): about
    when a slot frees if the requests ahead are like the recent ones.
    """

    def __init__(self, limit: int, what: str, setting: str) -> None:
        self.limit = max(1, limit)
        self.what = what
        self.setting = setting
        self.current = 0
        self.admitted = 0
        self.refused = 0
        self._avg_s: float | None = None

    def retry_after(self) -> int:
        avg = self._avg_s if self._avg_s is not None else 1.0
        return int(min(RETRY_AFTER_MAX_S, max(RETRY_AFTER_MIN_S, math.ceil(avg))))

    @contextmanager
    def enter(self) -> Iterator[None]:
        if self.current >= self.limit:
            self.refused += 1
            ra = self.retry_after()
            raise busy(f"{self.current} {self.what} in flight, the limit is {self.limit}; retry after {ra} s "
                       "(or POST the same body to /v1/jobs)", value=self.current,
                       rule=f"at most {self.limit} {self.what} at once ({self.setting})", retry_after=ra)
        self.current += 1
        self.admitted += 1
        t0 = time.monotonic()
        try:
            yield
        finally:
            self.current -= 1
            dt = time.monotonic() - t0
            self._avg_s = dt if self._avg_s is None else 0.8 * self._avg_s + 0.2 * dt

    def stats(self) -> dict[str, int]:
        return {"in_flight": self.current, "limit": self.limit, "admitted": self.admitted, "refused": self.refused}
