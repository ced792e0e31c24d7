"""The service with instrumented solver processes (``tests.service.gate_hook``), for the streaming tests:
``uvicorn tests.service.gated_app:app`` with FEEDSCHED_TEST_GATE_DIR set."""

from __future__ import annotations

import service.app as service_app
from service.config import Settings
from service.executor import Executor, LocalProcessExecutor


def _executor(workers: int, dask_scheduler: str | None) -> Executor:
    return LocalProcessExecutor(workers, preload=("service.worker", "tests.service.gate_hook"))


service_app.make_executor = _executor
app = service_app.create_app(Settings())
