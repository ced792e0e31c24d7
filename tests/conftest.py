"""Shared test set-up.

Schedules solve their NLP chains in this process unless a test asks for workers (``Options(nlp_workers=2)``):
probes that tests monkeypatch into the solvers record into this process's memory, which a forked worker's
calls would not reach, and pytest already runs on both cores (``-n 2``).  The default's own number, and the
forked workers' feed (the same bit for bit), are tested in ``tests/solvers/test_nlp.py``.
"""

from __future__ import annotations

import pytest


@pytest.fixture(autouse=True)
def _nlp_in_process(monkeypatch: pytest.MonkeyPatch) -> None:
    from solvers import pipeline

    monkeypatch.setattr(pipeline, "NLP_AUTO_WORKERS_MAX", 1)
