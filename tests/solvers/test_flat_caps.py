"""Control points under a flat velocity bound are held at it (``solvers.lp.flat_reach``, ``solvers.nlp.
flat_feed_columns``): a cruise at a feed cap is flat in the samples, not rippling about the cap.

Independent truth: the 1 kHz samples' own feed (and finite differences of their positions for the limits), and a
loop over the checkpoints for each column's bound."""

from __future__ import annotations

import numpy as np
import pytest

from geometry import examples as ex
from geometry import primitives
from geometry.toolpath import Toolpath
from solvers import bspline, lp, nlp
from solvers.machine import router
from solvers.pipeline import Options, schedule
from tests.fdcheck import utilisation
from tests.solvers.test_nlp import _check_drive
from tests.solvers.test_nlp_rest import _ramp_dip

TS = 1e-3
#: The feed over its cap (share of the cap) and its largest drop below its running maximum while it leaves rest
#: (or, reversed, reaches it), as a share of the cap: round-off (measured <= 2.4e-7 at 15-60 mm/s, both methods).
CAP_OVER = 1e-9
RIPPLE = 1e-5
#: Without the column bounds the same lines rippled by 1.2e-3 - 3.4e-3 of the cap (session 61); at least this.
RIPPLE_WITHOUT = 5e-4
#: FD limits as the issue's: <= 1.01 x (method lp's v, a, j; lp+nlp's u and e: ``_check_drive``).
LIMIT_FACTOR = 1.01


def _path(shape: str, cap: float) -> Toolpath:
    if shape == "circle":  # (r 100 mm: test_fidelity's gentle curve)
        return Toolpath([ex.circle(100.0)])
    return Toolpath([primitives.line(np.zeros(3), np.array([8.0 * cap, 2.4 * cap, 0.0]))])


@pytest.mark.parametrize(("method", "cap", "shape"), [
    ("lp", 8.0, "line"), ("lp", 60.0, "line"), ("lp+nlp", 15.0, "line"), ("lp+nlp", 60.0, "line"),
    ("lp+nlp", 50.0, "circle"),
])
def test_a_cruise_at_a_feed_cap_is_flat(monkeypatch: pytest.MonkeyPatch, method: str, cap: float, shape: str) -> None:
    """A line under a feed cap: the LP's control points alternated about the cap once it was reached (1.0116,
    0.9884, 1.0007, 0.9993 of it squared at 8 mm/s: integral q is the same), the feed 0.05 % over the cap between
    the checkpoints and 0.4 % under it; the NLP's did the same from 15 mm/s (the circle at 50 mm/s: 0.06 % over,
    1.7 % under, next to its rest intervals, ``nlp.REST_FLAT_SKIP``).  Now monotone to the cap and never over it,
    within the limits, and no slower than 0.1 ms."""
    m = router().with_feed_max(cap)
    sch = schedule(_path(shape, cap), m, Options(method=method))
    f = sch.samples.feed
    assert float(np.max(f)) <= cap * (1.0 + CAP_OVER)
    assert _ramp_dip(f, cap) <= RIPPLE
    if method == "lp":
        u = utilisation(sch.samples.position, TS, *m.limit_arrays())
        assert max(u.values()) <= LIMIT_FACTOR, u
    else:
        _check_drive(m, sch)  # (the NLP's limits: control signal and servo error)
    monkeypatch.setattr(lp, "FLAT_CAP_COLUMNS", False)
    monkeypatch.setattr(nlp, "FLAT_FEED_COLUMNS", False)
    off = schedule(_path(shape, cap), m, Options(method=method))
    assert _ramp_dip(off.samples.feed, cap) >= RIPPLE_WITHOUT  # (the test sees the ripple)
    assert sch.summary["motion_time"] <= off.summary["motion_time"] + 1e-4


def test_flat_reach_is_the_bound_where_it_is_the_same_over_the_support() -> None:
    d, n_int = 0.5, 12
    s = np.linspace(0.0, n_int * d, 6 * n_int + 1)
    cap = np.where(s < 2.6, 4.0, 9.0)  # a step between knots 5 and 6
    cap[s > 5.2] = np.inf  # nothing bounds the last stretch
    k, W0, _, _ = bspline.basis(s, d, n_int, 0, n_int - 1)
    got = lp.flat_reach(k, W0, cap, n_int + 2)
    for j in range(n_int + 2):  # loop: the points where b_j > 0
        on = [cap[i] for i in range(s.size) if any(k[i] + r == j and W0[i, r] > 0.0 for r in range(3))]
        want = on[0] if on and np.isfinite(on[0]) and all(c == on[0] for c in on) else np.inf
        assert got[j] == want, j
    assert list(got) == [4.0] * 5 + [np.inf] * 3 + [9.0] * 2 + [np.inf] * 4  # (the step; the unbounded stretch)


@pytest.mark.parametrize(("head", "tail"), [(False, False), (True, False), (True, True)])
def test_flat_feed_columns_reads_each_control_points_three_intervals(head: bool, tail: bool) -> None:
    n, N = 9, 4
    k, tau = nlp.checkpoint_layout(n, N)
    ub = np.where(k * 1.0 + tau < 4.5, 10.0, 20.0)
    got = nlp.flat_feed_columns(ub, n, N, head, tail)
    for j in range(n + 2):
        on = ub[(k >= j - 2) & (k <= j)]
        rest = (head and j < nlp.REST_FLAT_SKIP) or (tail and j >= n + 2 - nlp.REST_FLAT_SKIP)
        assert got[j] == (np.inf if rest or on.min() != on.max() else on[0]), j
