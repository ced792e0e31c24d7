"""Time tables by segments (``solvers.timing.PieceTiming``, ``TABLE_SEGMENT_INTERVALS``).

A piece longer than a segment is timed segment by segment and holds one segment's table at a time (bounded
memory for a corner-free path of any length).  Truth: the same piece timed as one table (the quadrature is
accurate to ~1e-13 s either way, so durations and inverses agree to that, not bit for bit), and the
schedule's own streamed and held outputs.
"""

from __future__ import annotations

import itertools
from dataclasses import replace
from typing import Any

import numpy as np
import pytest

from geometry import examples as ex
from geometry.quadrature import MonotoneTable
from solvers import pipeline as P
from solvers import timing as T
from solvers.machine import router
from solvers.timing import PieceProfile, PieceTiming

#: Duration of a piece timed in segments vs in one table, relative (each is within ~1e-13 of the integral).
DURATION_REL_TOL = 1e-12
#: s(t) from segments vs one table, mm (both ~1e-12 relative; path fidelity needs 1e-3 mm).
S_ABS_TOL = 1e-9
#: Sampled positions of a scheduled path, segments vs one table, mm.
POSITION_ABS_TOL = 1e-9


def _profile(n: int = 40) -> PieceProfile:
    c = 100.0 + 50.0 * np.sin(np.arange(n + 2) / 3.0)
    c[0], c[-1] = -c[1], -c[-2]  # rest at both ends
    return PieceProfile(s_start=0.0, length=float(n), d=1.0, c=c)


@pytest.mark.parametrize("segment", [8, 7, 39])
def test_segmented_table_is_the_one_table(segment: int, monkeypatch: pytest.MonkeyPatch) -> None:
    prof = _profile()
    whole = PieceTiming.build(prof)
    assert whole.edges.size == 2 and len(whole.held) == 1  # (40 intervals: one table, kept)
    monkeypatch.setattr(T, "TABLE_SEGMENT_INTERVALS", segment)
    builds: list[float] = []
    build = MonotoneTable.build.__func__  # type: ignore[attr-defined]

    def counted(cls: Any, f: Any, edges: np.ndarray, *a: Any, **kw: Any) -> MonotoneTable:
        builds.append(float(edges[0]))
        return build(cls, f, edges, *a, **kw)  # type: ignore[no-any-return]

    monkeypatch.setattr(MonotoneTable, "build", classmethod(counted))
    seg = PieceTiming.build(prof)
    n_seg = -(-prof.n_int // segment)
    assert seg.edges.size == n_seg + 1 and not seg.held  # (integral-only tables, none kept)
    assert len(builds) == n_seg
    assert seg.duration == pytest.approx(whole.duration, rel=DURATION_REL_TOL, abs=0.0)
    # sorted times across every segment, the edges themselves and beyond both ends
    t = np.sort(np.concatenate([np.linspace(-0.1, seg.duration + 0.1, 997), seg.t_edges]))
    builds.clear()
    s = seg.s_at(t)
    np.testing.assert_allclose(s, whole.s_at(t), rtol=0.0, atol=S_ABS_TOL)
    assert s[0] == 0.0 and s[-1] == prof.length
    assert np.all(np.diff(s) >= 0.0)
    assert sorted(builds) == builds and len(builds) == n_seg  # each segment built once, in order
    assert len(seg.held) == 1  # one table held at a time
    # a later call inside the held segment builds nothing
    builds.clear()
    seg.s_at(t[-3:])
    assert not builds


@pytest.mark.parametrize("method", ["lp", "lp+nlp"])
def test_streamed_long_piece_with_segmented_tables(method: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """The flower (one piece, ~150-300 knot intervals) timed in segments of 16 intervals and streamed in blocks:
    the stream is ``schedule()`` bit for bit, and both are the one-table schedule to within the quadrature's
    accuracy."""
    tp, m = ex.flower(), router()
    opt = P.Options(method=method)
    one = P.schedule(tp, m, opt)
    monkeypatch.setattr(T, "TABLE_SEGMENT_INTERVALS", 16)
    monkeypatch.setattr(P, "SAMPLE_CHUNK", 256)
    seg = P.schedule(tp, m, opt)
    assert one.profiles[0].n_int > 4 * 16
    blocks = [b for b in P.schedule_stream(tp, m, opt, block_samples=512) if isinstance(b, P.SampleBlock)]
    assert len(blocks) > 2
    joined = P.concat_samples([b.samples for b in blocks])
    for col in ("t", "s", "feed", "position", "velocity", "acceleration", "jerk"):
        assert np.array_equal(getattr(joined, col), getattr(seg.samples, col)), col
    assert seg.summary["motion_time"] == pytest.approx(one.summary["motion_time"], rel=DURATION_REL_TOL, abs=0.0)
    assert seg.samples.t.size == one.samples.t.size
    np.testing.assert_allclose(seg.samples.position, one.samples.position, rtol=0.0, atol=POSITION_ABS_TOL)
    # the binding checkpoints, evaluated SAMPLE_CHUNK at a time: those of evaluating all at once
    assert one.summary["checkpoints"] > 3 * 256
    assert seg.diagnostics["binding"] == one.diagnostics["binding"]
    assert any(v["count"] for v in one.diagnostics["binding"].values())


#: Table nodes per knot interval of a smooth, steep interval (the quadrature splits each in two, then bisects
#: where 16-point rules disagree, and where the inverse's guess misses ``TIME_GUESS_TOL_S``: 27 nodes at 1e-8 s,
#: the same interval near the piece start too; 8 at 1e-6 s; the noisy integrand took 2,081).
CLEAN_NODES_PER_INTERVAL = 32


def test_far_along_a_long_piece_the_time_integrand_is_not_noisy() -> None:
    """Knot interval 59,012 of the 367 m flower's LP profile (q's control points 1612.6, 18.87, 12878.5 mm^2/s^2):
    evaluated at s = d x and back, h(x) had a relative noise of ~1e-10 there, and the time table bisected that
    interval into 2,081 nodes (one 8192-interval segment: 0.88 M nodes, +100 MB).  In segment-local
    coordinates it needs the same few nodes as the same interval near the piece start."""
    n, k = 59_100, 59_012
    steep = np.array([1612.5898927, 18.87003261, 12878.50814352])
    c = np.full(n + 2, 1000.0)
    c[0], c[-1] = -c[1], -c[-2]  # rest at both ends
    c[k : k + 3] = steep
    d = 4.63
    prof = PieceProfile(s_start=0.0, length=n * d, d=d, c=c)
    seg = T.TABLE_SEGMENT_INTERVALS
    x0 = (k // seg) * seg
    table = T._segment_table(prof, float(x0), float(n), True)
    in_k = np.count_nonzero(np.floor(table.x_b[:-1]) == k - x0)
    assert in_k <= CLEAN_NODES_PER_INTERVAL
    # the same interval near the start: the same integral
    c2 = np.full(20 + 2, 1000.0)
    c2[0], c2[-1] = -c2[1], -c2[-2]
    c2[10:13] = steep
    near = T._segment_table(PieceProfile(s_start=0.0, length=20 * d, d=d, c=c2), 0.0, 20.0, True)
    j = np.searchsorted(table.x_b, [k - x0, k - x0 + 1])
    i = np.searchsorted(near.x_b, [10.0, 11.0])
    assert table.F_b[j[1]] - table.F_b[j[0]] == pytest.approx(near.F_b[i[1]] - near.F_b[i[0]], rel=DURATION_REL_TOL)
    assert in_k <= np.count_nonzero(np.floor(near.x_b[:-1]) == 10) + 2


def _dipping_profile(rng: np.random.Generator, n: int = 60) -> PieceProfile:
    """Random f and q control points with dips inside intervals (f to ~1e-6 of the feed around), nearly straight
    intervals (A ~ 0, either sign), concave ones, and lows of q at knots."""
    p = rng.uniform(5.0, 200.0, n + 2)
    for k in range(1, n - 1, 5):
        # interval k dips to f(1/2) ~ 1e-4 .. 1 (f = p_k / 3 at its knots), k + 1 is nearly straight
        p[k + 2] = p[k]
        p[k + 1] = -p[k] / 3.0 + 10.0 ** rng.uniform(-4, 0)
        p[k + 3] = 2.0 * p[k + 2] - p[k + 1] + rng.normal() * 10.0 ** rng.uniform(-14, -2)
    c = rng.uniform(5.0, 200.0, n + 2) ** 2
    for k in range(1, n - 1, 5):
        c[k + 2] = c[k]
        c[k + 1] = -c[k] / 3.0 + 10.0 ** rng.uniform(-4, 2)
        c[k + 3] = 2.0 * c[k + 2] - c[k + 1] + rng.normal() * 10.0 ** rng.uniform(-14, -2)
    for k in range(3, n - 1, 10):
        c[k + 1] = -c[k] + 10.0 ** rng.uniform(-3, 1)  # q ~ 1e-3 .. 10 at knot k (next to ~1e4)
    c[0], c[-1] = -c[1], -c[-2]
    return PieceProfile(s_start=0.0, length=float(n) * 0.5, d=0.5, c=c, p=p, f_mask=np.ones(n, dtype=bool))


@pytest.mark.filterwarnings("ignore::scipy.integrate.IntegrationWarning")
def test_interval_times_are_the_time_integrals() -> None:
    """``interval_times`` (the NLP span guard, ``solvers.pipeline._slower_spans``) against adaptive quadrature split
    at each quadratic's vertex and graded towards it: exact closed forms, so deep dips between checkpoints,
    nearly straight and concave intervals and lows at knots are all within 1e-9; inf where the feed reaches 0."""
    from scipy.integrate import quad

    rng = np.random.default_rng(7)
    for _ in range(3):
        prof = _dipping_profile(rng)
        k = np.arange(1, prof.n_int - 1)
        # f on every interval (``_dipping_profile``), then q alone (the same profile without f)
        for refined, cp, power in ((True, prof.p, 1.0), (False, prof.c, 0.5)):
            assert cp is not None
            got = T.interval_times(prof if refined else replace(prof, p=None, f_mask=None), k)
            for j, kk in enumerate(k):
                a, b, e = cp[kk], cp[kk + 1], cp[kk + 2]
                A, B, C = 0.5 * (a - 2.0 * b + e), b - a, 0.5 * (a + b)

                def g(t: float, A: float = A, B: float = B, C: float = C) -> float:
                    return (A * t + B) * t + C

                tv = -B / (2.0 * A) if A > 0.0 and 0.0 < -B / (2.0 * A) < 1.0 else 0.0
                if min(g(t) for t in np.linspace(0.0, 1.0, 2001)) <= 0.0 or g(tv) <= 0.0:
                    assert got[j] == np.inf
                    continue
                cuts = sorted({min(max(tv + sg * 10.0**-i, 0.0), 1.0) for sg in (-1, 1) for i in range(1, 9)}
                              | {tv, 0.0, 1.0})
                ref = prof.d * sum(quad(lambda t, pw=power: g(t) ** -pw, lo, hi, epsabs=0.0, epsrel=1e-13,
                                        limit=400)[0] for lo, hi in itertools.pairwise(cuts) if hi > lo)
                assert got[j] == pytest.approx(ref, rel=1e-9), (refined, kk, A, B, C)
    # f reaching 0 inside an interval, and q at a knot
    prof = _profile()
    p = np.sqrt(np.abs(prof.c))
    p[11] = -(p[10] + p[12]) / 6.0 - 1e-9
    dip = replace(prof, p=p, f_mask=np.ones(prof.n_int, dtype=bool))
    assert T.interval_times(dip, np.array([9, 10, 11]))[1] == np.inf
    c = prof.c.copy()
    c[21] = -c[20]
    assert np.all(T.interval_times(replace(prof, c=c, p=None, f_mask=None), np.array([19, 20])) == np.inf)


#: s(t) in the rest intervals against adaptive quadrature and root finding, mm (measured ~1e-15 mm with
#: TIME_GUESS_TOL_S = 1e-8; with 1e-6 the one Newton step left 1.2e-11 (v+a) and 8.8e-11 mm (with jerk) there)
REST_S_ABS_TOL = 1e-12


@pytest.mark.filterwarnings("ignore::scipy.integrate.IntegrationWarning")
@pytest.mark.parametrize("jerk", [False, True])
def test_time_samples_in_the_rest_intervals_match_quadrature(jerk: bool) -> None:
    """The flower's LP profile (with jerk: the rest shapes too): s at the sample times in the first and the last
    knot interval against t(x) = integral_0^x h by scipy's adaptive quad, inverted by brentq to 1e-16 in x.
    h jumps at the rest intervals' inner knots (``MonotoneTable``'s one-sided values there)."""
    from scipy.integrate import quad
    from scipy.optimize import brentq

    sch = P.schedule(ex.flower(), router(), P.Options(method="lp", jerk=jerk))
    prof = sch.profiles[0]
    assert len(sch.profiles) == 1
    n = prof.n_int
    t = sch.samples.t
    tm = PieceTiming.build(prof)
    s = tm.s_at(t)
    np.testing.assert_array_equal(s, sch.samples.s)  # (the schedule's own samples)

    def h(x: float) -> float:
        return float(prof.h(np.array([x]))[0])

    t_end = tm.duration
    for head in (True, False):
        lo, hi = (0.0, 1.0) if head else (n - 1.0, float(n))
        s_lo, s_hi = prof.s_of_x(np.array([lo, hi]))[0]
        k = np.flatnonzero((s > s_lo) & (s < s_hi))
        assert k.size >= 10
        for i in k[:: max(1, k.size // 12)]:
            if head:
                def resid(x: float, i: int = i) -> float:
                    return quad(h, 0.0, x, epsabs=1e-17, epsrel=1e-15, limit=200)[0] - t[i]
            else:  # from the end: t_end - t(x) = integral_x^n h
                def resid(x: float, i: int = i) -> float:
                    return (t_end - t[i]) - quad(h, x, float(n), epsabs=1e-17, epsrel=1e-15, limit=200)[0]
            x = brentq(resid, lo, hi, xtol=1e-16, rtol=1e-15)
            assert abs(s[i] - prof.s_of_x(np.array([x]))[0][0]) <= REST_S_ABS_TOL, (head, i, s[i])
