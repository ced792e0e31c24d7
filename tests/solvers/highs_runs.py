"""A hook on every HiGHS run of the LP (``solvers.lp.WindowLP._timed_run``), for tests that record the runs."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pytest

from solvers import lp


def watch_highs_runs(monkeypatch: pytest.MonkeyPatch, after: Callable[[Any], None] | None = None,
                     before: Callable[[Any], None] | None = None) -> None:
    """Calls ``before(h)`` and ``after(h)`` with the ``highspy.Highs`` model around each of its runs."""
    run = lp.WindowLP._timed_run

    def watched(h: Any) -> None:
        if before is not None:
            before(h)
        run(h)
        if after is not None:
            after(h)

    monkeypatch.setattr(lp.WindowLP, "_timed_run", staticmethod(watched))
