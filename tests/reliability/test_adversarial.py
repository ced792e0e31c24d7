"""Adversarial geometry and limits (issue 5, item 2), each with a defined outcome.

Outcome "schedule": both methods return samples that the independent checker
(``tests.reliability.checker``) accepts: limits within 1.01 x, every sample within 1 um of
the path, fixed period, rest at ends and corners.  Outcome "error": a typed error
(GeometryError / ScheduleError) naming the field, or a service problem naming it.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient

from geometry import primitives
from geometry.errors import GeometryError
from geometry.nurbs import NurbsSegment
from geometry.toolpath import Toolpath
from service.app import create_app
from service.config import Settings
from solvers.errors import ScheduleError
from solvers.machine import Axis, AxisLimits, Machine, router
from solvers.pipeline import Options, schedule
from tests.reliability import checker, gen

TS = 1e-3
#: Parabola y = x^2 / (2 r) as one quadratic Bezier: curvature radius r at the vertex (mm).
TIGHT_RADIUS_MM = 1e-4
#: Control points in a million-point toolpath (issue: size cap).
MILLION = 1_000_000
#: Long path (mm) of the issue.
KILOMETRE_MM = 1e6

Builder = Callable[[], list[NurbsSegment]]


def _data(segs: list[NurbsSegment]) -> list[checker.Nurbs]:
    return [checker.Nurbs(s.degree, s.knots, s.control_points, s.weights) for s in segs]


def _schedules_within_limits(segs: list[NurbsSegment], m: Machine, methods: tuple[str, ...]) -> None:
    tp = Toolpath(segs)
    for method in methods:
        sch = schedule(tp, m, Options(method=method, sample_period=TS))
        smp = sch.samples
        rep = checker.check(_data(segs), gen.limits_of(m), TS, smp.t, smp.feed, smp.position,
                            kinematic=method == "lp", drive=method == "lp+nlp")
        assert rep.ok, (method, rep.violations)


def _parabola(a: float, r: float) -> list[NurbsSegment]:
    h = a * a / (2.0 * r)
    return [NurbsSegment.create(2, [0, 0, 0, 1, 1, 1], [[-a, h], [0.0, -h], [a, h]])]


SCHEDULE_CASES: dict[str, Builder] = {
    # a double control point inside a cubic: |C'| vanishes at one parameter, no cusp
    "zero_length_span": lambda: [NurbsSegment.create(
        3, [0, 0, 0, 0, 0.3, 0.6, 1, 1, 1, 1], [[0, 0], [5, 0], [10, 2], [10, 2], [15, 5], [20, 5]])],
    "curvature_radius_below_1um": lambda: _parabola(0.01, TIGHT_RADIUS_MM),
    # second segment starts 0.5 um off the first one's end (within the 1e-3 mm gap tolerance): closed
    "near_coincident_segments": lambda: [primitives.line([0, 0, 0], [10, 0, 0]),
                                         primitives.line([10, 0, 5e-4], [20, 0, 5e-4])],
    # the second segment runs back over the first (a 180 degree corner)
    "reversal_onto_itself": lambda: [primitives.line([0, 0, 0], [10, 0, 0]),
                                     primitives.line([10, 0, 0], [1e-3, 1e-6, 0])],
    "path_of_1um": lambda: [primitives.line([0, 0, 0], [1e-3, 0, 0])],
    "z_only": lambda: [primitives.line([0, 0, 0], [0, 0, -25])],
}


#: Cases whose outcome today is not the defined one (strict: a fix shows up as XPASS).
KNOWN_BAD: dict[str, str] = {}


@pytest.mark.parametrize("name", [
    pytest.param(n, marks=[pytest.mark.xfail(reason=KNOWN_BAD[n], strict=True)] if n in KNOWN_BAD else [])
    for n in sorted(SCHEDULE_CASES)
])
@pytest.mark.filterwarnings("ignore::RuntimeWarning")
def test_adversarial_geometry_schedules(name: str) -> None:
    _schedules_within_limits(SCHEDULE_CASES[name](), router(), ("lp", "lp+nlp"))


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
def test_cusp_inside_a_segment_is_a_rest_point() -> None:
    """Three equal control points in a cubic: |C'| = 0 at the knot u = 0.5 and the tangent turns by
    135 degrees there (a cusp).  The segment is split at that knot (raised to multiplicity p), so the
    Toolpath sees a corner: the schedule comes to rest at the cusp, (10, 0), and the samples pass the
    independent checker with both methods."""
    seg = NurbsSegment.create(3, [0, 0, 0, 0, 0.5, 1, 1, 1, 1], [[0, 0], [10, 0], [10, 0], [10, 0], [0, 10]])
    tp = Toolpath([seg])
    assert len(tp.corners) == 1
    np.testing.assert_allclose(tp.corners[0].position, [10.0, 0.0, 0.0], atol=1e-12)
    assert tp.corners[0].angle_deg == pytest.approx(135.0, abs=0.5)
    _schedules_within_limits([seg], router(), ("lp", "lp+nlp"))


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
@pytest.mark.parametrize("method", ["lp", "lp+nlp"])
def test_knot_span_1e12_schedules_or_is_a_typed_error(method: str) -> None:
    """Knots 0.5 and 0.5 + 1e-12 in a cubic: the third derivative spikes in the tiny span and the
    LP feed used to dip to ~1e-14 of its peak there (the time quadrature then bisected for minutes).
    Defined outcome: a schedule the independent checker accepts (the piece is re-solved on finer
    knots when its feed stalls), or a ScheduleError on field ``toolpath``."""
    seg = NurbsSegment.create(3, [0, 0, 0, 0, 0.5, 0.5 + 1e-12, 1, 1, 1, 1],
                              [[0, 0], [5, 3], [10, -2], [15, 4], [20, 0], [25, 2]])
    try:
        _schedules_within_limits([seg], router(), (method,))
    except ScheduleError as err:
        assert err.field == "toolpath", err


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
def test_more_than_p_plus_1_end_knots_rejected() -> None:
    """[0,0,0,0,1,1,1] for degree 2: the first basis function vanishes, the curve would not start at
    P0.  Rule: a knot may repeat at most p + 1 times; the error names the knot."""
    with pytest.raises(GeometryError) as err:
        NurbsSegment.create(2, [0, 0, 0, 0, 1, 1, 1], [[0, 0], [1, 0], [2, 1], [3, 0]])
    assert err.value.field == "segment.knots[3]"
    assert "at most degree + 1 = 3" in err.value.rule
    with pytest.raises(GeometryError) as err:
        NurbsSegment.create(2, [0, 0, 0, 1, 1, 1, 1], [[0, 0], [1, 0], [2, 1], [3, 0]])
    assert err.value.field == "segment.knots[6]"


def _uniform(v: float) -> Machine:
    return Machine("uniform", tuple(Axis(a, AxisLimits(v, v, v), None) for a in "xyz"))  # type: ignore[arg-type]


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
@pytest.mark.parametrize(("limit", "length"), [
    (1e-3, 1e-3),
    (1e8, 1.0),  # HiGHS returned no status here before the LP's q scale was capped by the reachable q
    (1e10, 1.0),
    # HiGHS returned no status at 1e12 until the LP objective was normalised (its weights were ~Q ~ 1e12)
    (1e12, 1.0),
    (1e12, 100.0),
])
def test_extreme_limits_schedule(limit: float, length: float) -> None:
    """All limits 1e-3 (mm/s, mm/s^2, mm/s^3) or 1e12: the schedule holds them."""
    _schedules_within_limits([primitives.line([0, 0, 0], [length, length / 2, 0])], _uniform(limit), ("lp",))


@pytest.fixture(scope="module")
def client(tmp_path_factory: pytest.TempPathFactory) -> Iterator[TestClient]:
    data = Path(tmp_path_factory.mktemp("adv"))
    with TestClient(create_app(Settings(data_dir=data, workers=1))) as c:
        yield c


def test_million_control_points_hit_the_size_cap(client: TestClient) -> None:
    """A million control points: the body cap answers 413 before anything is parsed or solved."""
    pts = [[float(i), 0.0, 0.0] for i in range(MILLION)]
    body = {"toolpath": {"segments": [{"degree": 1, "knots": [0.0, *range(MILLION), MILLION - 1.0],
                                       "control_points": pts}]}, "machine": "router"}
    raw = json.dumps(body).encode()
    settings_cap = Settings().max_body_bytes
    assert len(raw) > settings_cap
    for route in ("/v1/schedule", "/v1/jobs"):
        r = client.post(route, content=raw, headers={"Content-Type": "application/json"})
        assert r.status_code == 413, r.text[:300]
        assert r.headers["content-type"].startswith("application/problem+json")


def test_kilometre_path_is_refused_synchronously(client: TestClient) -> None:
    """1e6 mm on the router needs ~4e5 knot intervals: over the synchronous budget, 413 naming the rule."""
    body = {"toolpath": {"segments": [{"degree": 1, "knots": [0, 0, 1, 1],
                                       "control_points": [[0, 0, 0], [KILOMETRE_MM, 0, 0]]}]},
            "machine": "router", "options": {"method": "lp"}}
    r = client.post("/v1/schedule", json=body)
    assert r.status_code == 413, r.text[:300]
    assert "intervals" in r.json()["detail"] or "samples" in r.json()["detail"]
