"""Drive rows next to rest ends (``solvers.lp.WindowLP._rest_drive_rows``, lp+nlp).

Truth: u and e recomputed by finite differences of the 1 kHz positions (tests/fdcheck.py) against the
drive model; and the same schedule with the rows off (``REST_DRIVE_INTERVALS`` = 0: the LP's a and j
caps there, as before), which must be slower near the rest ends.
"""

from __future__ import annotations

import numpy as np
import pytest

from geometry import examples as ex
from solvers import lp as LP
from solvers import nlp as NLP
from solvers.lp import LimitSet
from solvers.machine import router
from solvers.pipeline import Options, schedule
from tests.fdcheck import fd_drive

#: The sampled u and e may read up to this factor of their limits (issue 3).
SAMPLED_LIMIT = 1.01
#: Arc length from each rest end over which the time is compared, mm.
END_MM = 10.0


def _drive(m: object) -> dict[str, np.ndarray]:
    return m.drive_arrays()  # type: ignore[attr-defined, no-any-return]


def _end_times(sch: object, L: float) -> tuple[float, float]:
    S = sch.samples  # type: ignore[attr-defined]
    t0, t1 = np.interp([END_MM, L - END_MM], S.s, S.t)
    return float(t0), float(S.t[-1] - t1)


def test_flower_rest_ends_are_faster_and_within_the_drive_limits(monkeypatch: pytest.MonkeyPatch) -> None:
    # the LP's rows (where the rest intervals keep the LP's feed: ``solvers.nlp.REST_ENDS`` off; with it the
    # NLP's rest windows start from this LP feed, and a failed one falls back to it)
    monkeypatch.setattr(NLP, "REST_ENDS", False)
    tp, m = ex.flower(1), router()
    L = tp.length
    on = schedule(tp, m, Options())
    dr = _drive(m)
    u, e = fd_drive(on.samples.position, on.summary["sample_period"], dr)
    assert np.max(np.abs(u) / dr["umax"]) <= SAMPLED_LIMIT
    assert np.max(np.abs(e) / dr["emax"]) <= SAMPLED_LIMIT
    monkeypatch.setattr(LP, "REST_DRIVE_INTERVALS", 0)
    off = schedule(tp, m, Options())
    a_on, b_on = _end_times(on, L)
    a_off, b_off = _end_times(off, L)
    assert a_on < a_off and b_on < b_off
    assert on.summary["motion_time"] < off.summary["motion_time"]
    # in the rest interval (the LP's feed either way) the x acceleration stays within the router's amax
    # 500 with the rows off, and goes past it with them on (the servo error admits more)
    k = np.searchsorted(on.samples.s, on.summary["knot_spacing"])
    ax = np.max(np.abs(on.samples.acceleration[:k, 0]))
    assert ax > m.limit_arrays()[1][0] * 1.05
    assert np.max(np.abs(off.samples.acceleration[:k, 0])) <= m.limit_arrays()[1][0] * SAMPLED_LIMIT


def test_rows_only_under_lp_nlp_without_kinematic_rows() -> None:
    m = router()
    assert LimitSet.from_machine(m, 1e-3, True).rest_drive is None
    assert LimitSet.from_machine(m, 1e-3, True, rest_from_drive=True, kinematic=True).rest_drive is None
    assert LimitSet.from_machine(m, 1e-3, True, rest_from_drive=True).rest_drive is not None
