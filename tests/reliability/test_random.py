"""Randomized property suite (issue 5, item 1): RANDOM_CASES seeded cases, both methods, independent checker.

Each case (``tests.reliability.gen.case(seed, "test")``: curvature-continuous random NURBS, lines,
arcs and circles, 2-D and 3-D, with corners and closed loops, 1-300 mm, random machines
spanning decades of limits) is scheduled with ``lp`` (checked: finite-difference v, a, j) and
``lp+nlp`` (checked: u, e and v from the drive parameters), plus path distance, period, rest at
ends and corners, feed continuity (``tests.reliability.checker``, which shares no solver code).

KNOWN_FAILURES lists the (seed, method) runs that the checker rejects on this code, each with
its class (see the README's reliability section); they run as ``xfail`` so a fix shows up as
XPASS, and every other run must pass.  Classes:

- rest-acceleration: the LP leaves a rest end with zero acceleration (q' = 0), ScheduleError;
- stall: the feed reaches 0 inside a piece (knots coarser than a sharp turn), ScheduleError;
- highs-notset: HiGHS returns no status (badly scaled windows on large machines), SolverFailure;
- lp-infeasible: an LP window is infeasible, InfeasibleError;
- lp-overshoot: sampled acceleration or jerk above 1.01 x limit (between verification points);
- servo-error (fixed, none left): sampled servo error above 1.01 x emax under lp+nlp, at corners
  (the two pieces' rest accelerations added up in the step) and at features narrower than the
  NLP's checkpoints (see tests/reliability/test_regressions.py).
"""

from __future__ import annotations

import pytest

from tests.reliability import gen, harness

#: Seeds 0 .. RANDOM_CASES - 1 run in ``make test`` (issue: at least 200).
RANDOM_CASES = 200

KNOWN_FAILURES: dict[int, dict[str, str]] = {
    6: {'lp+nlp': 'highs-notset'},
    8: {'lp': 'stall', 'lp+nlp': 'stall'},
    14: {'lp': 'stall', 'lp+nlp': 'stall'},
    25: {'lp': 'rest-acceleration', 'lp+nlp': 'rest-acceleration'},
    27: {'lp': 'lp-overshoot'},
    36: {'lp': 'lp-overshoot'},
    42: {'lp': 'highs-notset', 'lp+nlp': 'highs-notset'},
    46: {'lp': 'lp-overshoot'},
    53: {'lp': 'lp-overshoot'},
    54: {'lp': 'highs-notset', 'lp+nlp': 'highs-notset'},
    63: {'lp': 'lp-overshoot'},
    69: {'lp': 'highs-notset', 'lp+nlp': 'highs-notset'},
    70: {'lp': 'rest-acceleration', 'lp+nlp': 'rest-acceleration'},
    73: {'lp': 'lp-infeasible'},
    76: {'lp': 'rest-acceleration', 'lp+nlp': 'rest-acceleration'},
    77: {'lp': 'lp-overshoot'},
    78: {'lp': 'rest-acceleration', 'lp+nlp': 'rest-acceleration'},
    82: {'lp': 'lp-overshoot'},
    85: {'lp': 'rest-acceleration', 'lp+nlp': 'rest-acceleration'},
    101: {'lp': 'rest-acceleration', 'lp+nlp': 'rest-acceleration'},
    109: {'lp': 'lp-overshoot'},
    110: {'lp': 'highs-notset', 'lp+nlp': 'highs-notset'},
    121: {'lp': 'rest-acceleration', 'lp+nlp': 'rest-acceleration'},
    127: {'lp': 'lp-overshoot'},
    129: {'lp': 'rest-acceleration', 'lp+nlp': 'rest-acceleration'},
    133: {'lp': 'rest-acceleration', 'lp+nlp': 'rest-acceleration'},
    138: {'lp': 'lp-overshoot'},
    147: {'lp+nlp': 'rest-acceleration'},
    148: {'lp': 'highs-notset', 'lp+nlp': 'highs-notset'},
    151: {'lp': 'rest-acceleration', 'lp+nlp': 'rest-acceleration'},
    153: {'lp': 'lp-overshoot'},
    157: {'lp': 'lp-overshoot'},
    162: {'lp': 'highs-notset', 'lp+nlp': 'highs-notset'},
    174: {'lp': 'lp-overshoot'},
    178: {'lp': 'lp-overshoot'},
    182: {'lp': 'rest-acceleration', 'lp+nlp': 'rest-acceleration'},
    193: {'lp': 'stall', 'lp+nlp': 'stall'},
}


def _params() -> list[object]:
    out: list[object] = []
    for seed in range(RANDOM_CASES):
        for method in harness.METHODS:
            why = KNOWN_FAILURES.get(seed, {}).get(method)
            marks = [pytest.mark.xfail(reason=f"known failure class: {why}", strict=False)] if why else []
            out.append(pytest.param(seed, method, marks=marks, id=f"{seed}-{method}"))
    return out


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
@pytest.mark.parametrize(("seed", "method"), _params())
def test_random_case(seed: int, method: str) -> None:
    case = gen.case(seed, "test")
    out = harness.run(case, method)
    assert out.ok, f"{out.describe()} tags={case.tags}"


def test_generator_is_deterministic_and_varied() -> None:
    """Same seed, same case; the seeded subset covers the classes the issue asks for."""
    a, b = gen.case(7, "test"), gen.case(7, "test")
    assert [s.ctrl.tolist() for s in a.segments] == [s.ctrl.tolist() for s in b.segments]
    cases = [gen.case(s, "test") for s in range(RANDOM_CASES)]
    degrees = {s.degree for c in cases for s in c.segments}
    assert {2, 3, 4, 5} <= degrees
    assert {c.tags["dims"] for c in cases} == {2, 3}
    assert any(c.tags["closed"] for c in cases) and any(int(c.tags["corners"]) > 0 for c in cases)
    lengths = [c.length for c in cases]
    assert min(lengths) < 2.0 and max(lengths) > 100.0
    vmax = [a.limits.vmax for c in cases for a in c.machine.axes]
    assert max(vmax) / min(vmax) > 100.0  # limits span decades
    assert any(c.machine.feed_max is not None for c in cases)
    assert any(c.lp_machine is not c.machine for c in cases)
