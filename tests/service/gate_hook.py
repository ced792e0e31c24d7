"""Imported by the forkserver of ``tests.service.gated_app`` (so by every solver process it forks): wraps
``solvers.pipeline.solve_piece`` with controls read from files in $FEEDSCHED_TEST_GATE_DIR at each call.

- ``hold``: before the path's last piece is solved, write ``waiting-<pid>`` and wait until ``go`` exists,
  without a time limit: the last piece cannot finish before the test says so (the tests create ``go`` when
  they end, and a solver process exits with the service anyway).
- ``fail-<i>``: piece i raises ``LimitViolationError`` (as the sampled re-check does after its repairs).
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any

from solvers import pipeline
from solvers.errors import LimitViolationError

_solve_piece = pipeline.solve_piece


def _gated(toolpath: Any, piece: Any, *args: Any, **kwargs: Any) -> Any:
    gate = Path(os.environ.get("FEEDSCHED_TEST_GATE_DIR", "/nonexistent"))
    if (gate / f"fail-{piece.index}").exists():
        raise LimitViolationError("injected by the test: the sampled servo error reaches 1.5 x its limit",
                                  field="toolpath", value={"piece": piece.index}, axis="x")
    if piece.index == len(toolpath.pieces) - 1 and (gate / "hold").exists():
        (gate / f"waiting-{os.getpid()}").touch()
        while not (gate / "go").exists():
            time.sleep(0.01)
    return _solve_piece(toolpath, piece, *args, **kwargs)


pipeline.solve_piece = _gated
