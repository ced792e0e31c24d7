"""geometry.quadrature.MonotoneTable: integrals and inverses against closed forms, and the inverse
refinement's incremental re-check against re-checking every interval."""

from __future__ import annotations

import numpy as np
import pytest

from geometry.quadrature import MAX_BISECTIONS, QUINTIC_TOL, MonotoneTable, gauss_legendre
from solvers.timing import PieceProfile, PieceTiming

#: F(x) = integral_0^x f against the closed form, relative (the table's rule is 1e-13)
INTEGRAL_REL_TOL = 1e-12
#: x(F) after the Newton step against the closed form, absolute in x
INVERSE_ABS_TOL = 1e-11


def _f(x: np.ndarray) -> np.ndarray:
    """f = 1 + 0.9 sin(7 x) + 30 exp(-200 (x - 0.3)^2) > 0: smooth with a sharp bump."""
    return np.asarray(1.0 + 0.9 * np.sin(7.0 * x) + 30.0 * np.exp(-200.0 * (x - 0.3) ** 2))


def _df(x: np.ndarray) -> np.ndarray:
    """f'(x) of ``_f``."""
    return np.asarray(6.3 * np.cos(7.0 * x) - 12000.0 * (x - 0.3) * np.exp(-200.0 * (x - 0.3) ** 2))


def _F(x: np.ndarray) -> np.ndarray:
    from scipy.special import erf

    bump = 30.0 * np.sqrt(np.pi / 200.0) / 2.0 * (erf(np.sqrt(200.0) * (x - 0.3)) - erf(np.sqrt(200.0) * -0.3))
    return np.asarray(x + 0.9 / 7.0 * (1.0 - np.cos(7.0 * x)) + bump)


def _full_recheck(f: object, edges: np.ndarray, guess_tol: float) -> MonotoneTable:
    """The inverse refinement as it was until session 9: every interval re-checked each round."""
    table = MonotoneTable.build(f, edges, min_intervals=2, guess_tol=np.inf)  # type: ignore[arg-type]
    for _ in range(MAX_BISECTIONS):
        xa, xb = table.x_b[:-1], table.x_b[1:]
        xm = 0.5 * (xa + xb)
        Fm = table.F_b[:-1] + gauss_legendre(table.f, xa, xm)
        guess = table._hermite(Fm, np.arange(xa.size))
        bad = np.abs(guess - xm) * table.f(xm) > guess_tol
        if not bad.any():
            break
        at = np.flatnonzero(bad) + 1
        table = MonotoneTable(table.f, np.insert(table.x_b, at, xm[bad]), np.insert(table.F_b, at, Fm[bad]),
                              np.insert(table.f_b, at, table.f(xm[bad])))
    return table


@pytest.mark.parametrize("guess_tol", [1e-4, 1e-7, 1e-10])
def test_incremental_inverse_refinement_builds_the_table_of_the_full_recheck(guess_tol: float) -> None:
    edges = np.linspace(0.0, 2.0, 5)
    inc = MonotoneTable.build(_f, edges, min_intervals=2, guess_tol=guess_tol)
    ref = _full_recheck(_f, edges, guess_tol)
    assert inc.x_b.size > 2 * 4 + 1  # (the refinement split intervals)
    np.testing.assert_array_equal(inc.x_b, ref.x_b)
    np.testing.assert_array_equal(inc.F_b, ref.F_b)
    np.testing.assert_array_equal(inc.f_b, ref.f_b)


def test_integral_and_inverse_match_the_closed_form() -> None:
    edges = np.linspace(0.0, 2.0, 5)
    table = MonotoneTable.build(_f, edges, min_intervals=2, guess_tol=1e-7)
    x = np.linspace(0.0, 2.0, 1001)
    np.testing.assert_allclose(table.value(x), _F(x), rtol=INTEGRAL_REL_TOL, atol=0.0)
    assert table.total == pytest.approx(float(_F(np.array([2.0]))[0]), rel=INTEGRAL_REL_TOL)
    np.testing.assert_allclose(table.inverse(_F(x)), x, rtol=0.0, atol=INVERSE_ABS_TOL)


def test_integral_only_table_has_the_same_total_and_refuses_to_invert() -> None:
    edges = np.linspace(0.0, 2.0, 5)
    full = MonotoneTable.build(_f, edges, min_intervals=2, guess_tol=1e-7)
    only = MonotoneTable.build(_f, edges, min_intervals=2, guess_tol=np.inf)
    assert only.total == full.total
    assert only.x_b.size < full.x_b.size
    # a piece's time table: same duration either way, and a duration-only table will not sample
    n = 40
    c = 100.0 + 50.0 * np.sin(np.arange(n + 2) / 3.0)
    c[0], c[-1] = -c[1], -c[-2]  # rest at both ends
    prof = PieceProfile(s_start=0.0, length=float(n), d=1.0, c=c)
    timed, dur = PieceTiming.build(prof), PieceTiming.build(prof, inverse=False)
    assert dur.duration == timed.duration
    with pytest.raises(ValueError, match="duration only"):
        dur.s_at(np.array([0.5 * timed.duration]))


def test_chunked_evaluation_builds_the_same_table(monkeypatch: pytest.MonkeyPatch) -> None:
    """The integrand at breakpoints and midpoints is evaluated EVAL_CHUNK points at a time (bounded transients
    on long pieces): the table is the one of evaluating every point at once, bit for bit."""
    import geometry.quadrature as Q

    edges = np.linspace(0.0, 2.0, 5)
    whole = MonotoneTable.build(_f, edges, min_intervals=2, guess_tol=1e-10)
    sizes: list[int] = []

    def f(x: np.ndarray) -> np.ndarray:
        sizes.append(x.size)
        return _f(x)

    monkeypatch.setattr(Q, "EVAL_CHUNK", 7)
    chunked = MonotoneTable.build(f, edges, min_intervals=2, guess_tol=1e-10)
    assert sizes.count(7) > 100  # (the breakpoints and midpoints, in chunks)
    for col in ("x_b", "F_b", "f_b"):
        assert np.array_equal(getattr(chunked, col), getattr(whole, col)), col


def _newton_only(table: MonotoneTable, y: np.ndarray) -> np.ndarray:
    """The inverse by the cubic guess and the Newton step alone (the table without its quintic flags)."""
    from dataclasses import replace

    return replace(table, quintic=None).inverse(y)


def test_quintic_guess_leaves_the_table_and_stands_for_the_newton_step() -> None:
    """With f' given, the table is the same bit for bit (the solvers' cubic guess is unchanged), most
    intervals take the quintic guess at 1e-10, and the inverse matches the closed form and the Newton
    step's to within QUINTIC_TOL (in F's units, as the midpoint check measures it)."""
    edges = np.linspace(0.0, 2.0, 5)
    plain = MonotoneTable.build(_f, edges, min_intervals=2, guess_tol=1e-10)
    table = MonotoneTable.build(_f, edges, min_intervals=2, guess_tol=1e-10, df=_df)
    for col in ("x_b", "F_b", "f_b"):
        np.testing.assert_array_equal(getattr(table, col), getattr(plain, col))
    assert plain.quintic is None and table.quintic is not None
    assert table.quintic.mean() > 0.9
    x = np.linspace(0.0, 2.0, 20001)
    y = _F(x)
    got = table.inverse(y)
    np.testing.assert_allclose(got, x, rtol=0.0, atol=INVERSE_ABS_TOL)
    np.testing.assert_array_equal(table.inverse(y, newton=False), plain.inverse(y, newton=False))
    j = np.clip(np.searchsorted(table.F_b, y, side="right") - 1, 0, table.F_b.size - 2)
    q = table.quintic[j]
    assert q.mean() > 0.9
    miss = np.abs(got - _newton_only(table, y)) * _f(x)
    assert miss[q].max() <= 2.0 * QUINTIC_TOL
    # elsewhere the Newton step itself
    np.testing.assert_array_equal(got[~q], _newton_only(table, y)[~q])


def test_a_wrong_derivative_fails_the_midpoint_check_and_the_newton_step_takes_over() -> None:
    """f' off by a constant: the quintic guess misses at the midpoints, so (almost) no interval is flagged
    and the inverse is the Newton step's bit for bit where it is not."""
    edges = np.linspace(0.0, 2.0, 5)
    table = MonotoneTable.build(_f, edges, min_intervals=2, guess_tol=1e-10, df=lambda x: _df(x) + 50.0)
    assert table.quintic is not None and table.quintic.mean() < 0.05
    x = np.linspace(0.0, 2.0, 20001)
    y = _F(x)
    got = table.inverse(y)
    np.testing.assert_allclose(got, x, rtol=0.0, atol=INVERSE_ABS_TOL)
    j = np.clip(np.searchsorted(table.F_b, y, side="right") - 1, 0, table.F_b.size - 2)
    q = table.quintic[j]
    np.testing.assert_array_equal(got[~q], _newton_only(table, y)[~q])


def _f_jump(x: np.ndarray) -> np.ndarray:
    """1 + 0.3 sin(x), halved from x = 1 on: a jump of f at an edge (a time table's x map at a rest interval's
    inner knot)."""
    return np.asarray(np.where(x < 1.0, 1.0, 0.5) + 0.3 * np.sin(x))


def _F_jump(x: np.ndarray) -> np.ndarray:
    left = x + 0.3 * (1.0 - np.cos(x))
    at1 = 1.0 + 0.3 * (1.0 - np.cos(1.0))
    return np.asarray(np.where(x < 1.0, left, at1 + 0.5 * (x - 1.0) + 0.3 * (np.cos(1.0) - np.cos(x))))


def test_a_jump_at_an_edge_keeps_both_sides_and_needs_no_bisection_towards_it() -> None:
    """f jumps at the edge x = 1.  Given as a jump, the guesses read f from each interval's own side and the
    table is as coarse as a smooth f's; not given, the guesses on the left of x = 1 take the right side's slope
    and the intervals next to it are bisected round after round.  Integral and inverse against the closed form
    either way."""
    edges = np.linspace(0.0, 3.0, 4)
    plain = MonotoneTable.build(_f_jump, edges, min_intervals=2, guess_tol=1e-8)
    sided = MonotoneTable.build(_f_jump, edges, min_intervals=2, guess_tol=1e-8, jumps=np.array([1.0]),
                                jump_eps=2.0**-40)
    assert sided.f_left is not None and sided.f_right is not None
    i = int(np.flatnonzero(sided.x_b == 1.0)[0])
    assert sided.f_left[i] == pytest.approx(1.0 + 0.3 * np.sin(1.0), rel=1e-11)
    assert sided.f_right[i] == pytest.approx(0.5 + 0.3 * np.sin(1.0), rel=1e-11)
    # without the jump: nodes crowd towards x = 1 from the left (each round halves the interval next to it)
    assert np.count_nonzero((plain.x_b > 0.99) & (plain.x_b < 1.0)) >= 5
    assert np.count_nonzero((sided.x_b > 0.99) & (sided.x_b < 1.0)) == 0
    assert sided.x_b.size < plain.x_b.size
    x = np.linspace(0.0, 3.0, 3001)
    for table in (plain, sided):
        np.testing.assert_allclose(table.value(x), _F_jump(x), rtol=INTEGRAL_REL_TOL, atol=0.0)
        np.testing.assert_allclose(table.inverse(_F_jump(x)), x, rtol=0.0, atol=INVERSE_ABS_TOL)


def test_a_table_that_round_off_keeps_from_converging_stops_at_its_budget(monkeypatch: pytest.MonkeyPatch) -> None:
    """An integrand whose halves never agree (noise at the last place: round-off) split every interval at every
    level, doubling them up to MAX_BISECTIONS times; the table now stops at its interval budget with
    ``TableTooLarge`` (session 58: weights 1e-16 : 1 : 1e-16 built 27 M breakpoints).  A smooth integrand on the
    same budget converges."""
    import geometry.quadrature as q

    monkeypatch.setattr(q, "MAX_TABLE_INTERVALS", 4096)
    rng = np.random.default_rng(0)
    with pytest.raises(q.TableTooLarge) as err:
        MonotoneTable.build(lambda x: 1.0 + 1e-9 * rng.standard_normal(x.shape), np.array([0.0, 1.0]))
    assert err.value.budget == 4096 and err.value.intervals > 4096
    table = MonotoneTable.build(lambda x: 1.0 + x * x, np.array([0.0, 1.0]))
    assert table.total == pytest.approx(4.0 / 3.0, rel=1e-14)


def test_an_arc_length_that_does_not_converge_names_the_segment() -> None:
    """Weights 1e-30 : 1 : 1e-30: round-off holds the arc length's quadrature off at every level (a sync request ran
    to its 30 s budget, session 58's API probe).  The segment is refused naming it and its weights' spread."""
    from geometry.errors import GeometryError
    from geometry.nurbs import NurbsSegment
    from geometry.toolpath import Toolpath

    seg = NurbsSegment.create(2, [0, 0, 0, 1, 1, 1], [[0, 0, 0], [5, 5, 0], [10, 0, 0]], [1e-30, 1.0, 1e-30],
                              name="toolpath.segments[0]")
    with pytest.raises(GeometryError) as err:
        Toolpath([seg])
    assert err.value.field == "toolpath.segments[0]" and "does not converge" in err.value.rule
    assert err.value.value == {"weights_max_over_min": pytest.approx(1e30)}
    wide = NurbsSegment.create(2, [0, 0, 0, 1, 1, 1], [[0, 0, 0], [5, 5, 0], [10, 0, 0]], [1e-300, 1e300, 1e-300])
    with pytest.raises(GeometryError) as err:  # (a spread whose ratio overflows: the two ends, not "inf")
        Toolpath([wide])
    assert err.value.value == {"weights_max": 1e300, "weights_min": 1e-300}


def test_a_time_table_over_its_budget_is_a_schedule_error(monkeypatch: pytest.MonkeyPatch) -> None:
    """A piece's time table that cannot converge in its budget (1e9 s of motion: TIME_GUESS_TOL_S under the
    time's last place) is a ScheduleError naming the piece, not a run to the request's budget."""
    import geometry.quadrature as q
    from solvers.errors import ScheduleError

    n = 40
    c = 100.0 + 50.0 * np.sin(np.arange(n + 2) / 3.0)
    c[0], c[-1] = -c[1], -c[-2]
    prof = PieceProfile(s_start=7.0, length=float(n), d=1.0, c=c)
    monkeypatch.setattr(q, "MAX_TABLE_INTERVALS", 1)
    monkeypatch.setattr(q, "TABLE_GROWTH", 1)
    with pytest.raises(ScheduleError, match="time table of the piece does not converge") as err:
        PieceTiming.build(prof)
    assert err.value.field == "toolpath" and err.value.value["s_start"] == 7.0
