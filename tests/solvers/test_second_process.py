"""The second core outside the NLP: a long piece of method lp walks its LP windows as two chains joined by
a seam window (``pipeline._chain_split``, ``pipeline._walk_chains``), and a piece's time samples are
split in two halves (``pipeline._sample_piece``); with ``nlp_workers`` > 1 the second chain and the
second half in a forked process.

Truth here: the sampled limits by finite differences (tests/fdcheck.py, via test_limits._check), the
one-chain walk of the same windows (``LP_CHAIN_MIN_WINDOWS`` raised), and the in-process computation.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np
import pytest

from geometry import examples as ex
from solvers import pipeline
from solvers.errors import InfeasibleError
from solvers.lp import WindowLP, WindowSpec
from solvers.machine import router
from solvers.pipeline import LimitSet, Options, Schedule, schedule
from solvers.timing import PieceTiming
from tests.solvers.test_limits import _check

#: Motion time of the two chains against one chain, relative: the seam joins two states of the same
#: receding-horizon optimum (18.35 m: 194.278388 vs 194.278086 s, 1.6e-6).
SEAM_MOTION_RTOL = 1e-4
#: A seam window's last two control points against the fixed end state, relative to the largest.
END_FIXED_RTOL = 1e-9
#: Three flower loops in 30-interval windows (the overlap makes them 3 x the overlap): 10+ windows.
LOOPS = 3
WINDOW = 30


def _run(**kw: Any) -> Schedule:
    return schedule(ex.flower(LOOPS), router(), Options(method="lp", lp_window=WINDOW, **kw))


def _one_chain(monkeypatch: pytest.MonkeyPatch) -> Schedule:
    with monkeypatch.context() as mp:
        mp.setattr(pipeline, "LP_CHAIN_MIN_WINDOWS", 10**9)
        one = _run(nlp_workers=1)
    assert one.summary["lp_chains"] == 0
    return one


def _same_feed(a: Schedule, b: Schedule) -> None:
    assert a.summary["motion_time"] == b.summary["motion_time"]
    for pa, pb in zip(a.profiles, b.profiles, strict=True):
        np.testing.assert_array_equal(pa.c, pb.c)
    np.testing.assert_array_equal(a.samples.position, b.samples.position)


def test_two_chains_hold_the_limits_and_cost_no_motion(monkeypatch: pytest.MonkeyPatch) -> None:
    chains = _run(nlp_workers=1)
    assert chains.summary["lp_chains"] == 1 and chains.summary["lp_seam_fallbacks"] == 0
    assert chains.summary["windows"] >= 8
    util = _check(ex.flower(LOOPS), router(), chains)
    assert max(util.values()) > 0.95
    one = _one_chain(monkeypatch)
    rel = abs(chains.summary["motion_time"] / one.summary["motion_time"] - 1.0)
    assert rel <= SEAM_MOTION_RTOL, (chains.summary["motion_time"], one.summary["motion_time"])
    # the two walks differ (the test compares two solutions, not one twice)
    assert not np.array_equal(chains.profiles[0].c, one.profiles[0].c)


def _split_samples(monkeypatch: pytest.MonkeyPatch, break_forked: bool = False) -> list[int]:
    """Pieces of 1,000 samples or more split their sampling; returns the sizes of the halves this process
    fills (``break_forked``: the forked process's half fails)."""
    calls: list[int] = []
    orig = pipeline._fill_samples
    me = os.getpid()

    def fill(*args: Any) -> None:
        if os.getpid() != me:
            if break_forked:
                raise RuntimeError("sampling process broken by the test")
        else:
            calls.append(args[5].size)
        orig(*args)

    monkeypatch.setattr(pipeline, "_fill_samples", fill)
    monkeypatch.setattr(pipeline, "SAMPLE_SPLIT_MIN", 1000)
    return calls


def test_forked_second_chain_gives_the_same_feed(monkeypatch: pytest.MonkeyPatch) -> None:
    """The second chain and the second half of the samples in forked processes: the same schedule."""
    seq = _run(nlp_workers=1)
    calls = _split_samples(monkeypatch)
    par = _run(nlp_workers=2)
    assert calls and sum(calls) < seq.samples.t.size  # (half of them were sampled by the other process)
    assert par.summary["lp_chains"] == 1 and par.summary["lp_seam_fallbacks"] == 0
    _same_feed(par, seq)
    for k in ("windows", "solver_iterations", "cut_rounds", "cut_points"):
        assert par.summary[k] == seq.summary[k], k
    assert len(par.summary["window_times"]) == par.summary["windows"]


def test_failed_seam_walks_on_as_one_chain(monkeypatch: pytest.MonkeyPatch) -> None:
    """A seam window that fails leaves the first chain to walk on over the second one's knots: the one-chain
    feed bit for bit."""
    one = _one_chain(monkeypatch)
    orig = pipeline._WindowWalk.window

    def window(self: Any, *args: Any, **kw: Any) -> Any:
        if kw.get("end_fixed") is not None:
            raise InfeasibleError("seam made infeasible by the test", window=-1)
        return orig(self, *args, **kw)

    monkeypatch.setattr(pipeline._WindowWalk, "window", window)
    sch = _run(nlp_workers=1)
    assert sch.summary["lp_chains"] == 1 and sch.summary["lp_seam_fallbacks"] == 1
    _same_feed(sch, one)


def test_failed_forked_chain_walks_on_as_one_chain(monkeypatch: pytest.MonkeyPatch) -> None:
    """The forked second chain failing (any error in that process) is the same fallback."""
    one = _one_chain(monkeypatch)

    def broken(*args: Any, **kw: Any) -> Any:
        raise RuntimeError("second chain broken by the test")

    monkeypatch.setattr(pipeline, "_second_chain", broken)
    sch = _run(nlp_workers=2)
    assert sch.summary["lp_chains"] == 1 and sch.summary["lp_seam_fallbacks"] == 1
    _same_feed(sch, one)


def test_lp_nlp_short_pieces_and_given_overlaps_walk_one_chain() -> None:
    """The NLP hands out its chains while the LP walks (``on_lp``); a piece of fewer than
    LP_CHAIN_MIN_WINDOWS windows gains nothing from a second chain; a given overlap may be shorter than the
    stopping distance the second chain's start needs to be forgotten."""
    many = pipeline.WindowPlan(1.0, 2000, 200, 20, 60, 20)
    assert pipeline._chain_split(many, Options(method="lp+nlp")) is None
    assert pipeline._chain_split(many, Options(method="lp", lp_overlap=20)) is None
    few = pipeline.WindowPlan(1.0, 3 * 180, 200, 20, 60, 20)
    assert len(pipeline._plan_starts(few)) < pipeline.LP_CHAIN_MIN_WINDOWS
    assert pipeline._chain_split(few, Options(method="lp")) is None
    starts = pipeline._plan_starts(many)
    k_split, k_b, k_seam = pipeline._chain_split(many, Options(method="lp")) or (0, 0, 0)
    assert k_split in starts and k_b == k_split - 20 and k_split < k_seam <= k_b + 200 - 20 - 2
    assert sum(k < k_split for k in starts) == (len(starts) + 1) // 2


def test_seam_window_ends_in_the_fixed_state() -> None:
    """A window with ``end_fixed`` ends in that state (c_k1, c_k1+1) and admits the next solution there."""
    tp = ex.flower(1)
    m = router()
    opt = Options(method="lp")
    piece = tp.pieces[0]
    plan = pipeline.plan_piece(piece, m, opt)
    lim = LimitSet.from_machine(m, opt.sample_period, opt.jerk)
    geo = pipeline._local(tp, piece)
    br = pipeline._breaks(tp, piece)
    n = plan.n_int
    s_all = np.linspace(0.0, n * plan.d, n * opt.checkpoints_per_interval + 1)
    whole = WindowLP(WindowSpec(0, 0, n, plan.d, n, None, True), lim, geo, "highs", br).solve(s_all)
    k0, k1 = n // 3, n // 3 + 40
    spec = WindowSpec(1, k0, k1, plan.d, n, (float(whole.c[k0]), float(whole.c[k0 + 1])), False,
                      (0, whole.c_star), (0, whole.c), end_fixed=(float(whole.c[k1]), float(whole.c[k1 + 1])),
                      next_c=(0, whole.c), next_qstar=(0, whole.c_star))
    s = np.linspace(k0 * plan.d, k1 * plan.d, (k1 - k0) * opt.checkpoints_per_interval + 1)
    seam = WindowLP(spec, lim, geo, "highs", br).solve(s)
    scale = float(np.max(whole.c))
    np.testing.assert_allclose(seam.c[-2:], whole.c[k1 : k1 + 2], rtol=0, atol=END_FIXED_RTOL * scale)
    np.testing.assert_allclose(seam.c[:2], whole.c[k0 : k0 + 2], rtol=0, atol=END_FIXED_RTOL * scale)
    # between the two fixed ends it reaches the whole-piece optimum's feed (to the LP's tolerance)
    assert np.sum(seam.c) >= (1 - SEAM_MOTION_RTOL) * np.sum(whole.c[k0 : k1 + 2])


def _piece() -> tuple[Any, Any, int]:
    """One flower loop's lp+nlp profile and its sample count."""
    tp = ex.flower(1)
    sch = schedule(tp, router(), Options(method="lp+nlp", nlp_workers=1))
    return tp, sch.profiles[0], sch.samples.t.size


def _sample(tp: Any, prof: Any, K: int, workers: int) -> Any:
    return pipeline._sample_piece(tp, tp.pieces[0], prof, PieceTiming.build(prof), 0.0, 0, K, 1e-3, workers)


COLUMNS = ("t", "s", "feed", "position", "velocity", "acceleration", "jerk")


def test_split_sampling_gives_the_same_samples(monkeypatch: pytest.MonkeyPatch) -> None:
    """The forked half of a piece's samples: bit for bit the samples of one process (the values are
    elementwise in t)."""
    tp, prof, K = _piece()
    one = _sample(tp, prof, K, 1)
    calls = _split_samples(monkeypatch)
    two = _sample(tp, prof, K, 2)
    assert calls == [K // 2]  # (this process's half: the other one was the forked process's)
    for col in COLUMNS:
        np.testing.assert_array_equal(getattr(two, col), getattr(one, col), err_msg=col)


def test_failed_sampling_process_leaves_its_half_to_this_one(monkeypatch: pytest.MonkeyPatch) -> None:
    tp, prof, K = _piece()
    one = _sample(tp, prof, K, 1)
    calls = _split_samples(monkeypatch, break_forked=True)
    two = _sample(tp, prof, K, 2)
    assert calls == [K // 2, K - K // 2]  # (its own half, then the failed process's)
    for col in COLUMNS:
        np.testing.assert_array_equal(getattr(two, col), getattr(one, col), err_msg=col)


@pytest.mark.parametrize("workers", [1, 2])
def test_held_samples_are_placed_before_the_pieces_own(monkeypatch: pytest.MonkeyPatch, workers: int) -> None:
    """``_sample_piece(..., held)``: the held rows, then the piece's own, bit for bit ``concat_samples`` of the
    two (in one process, and with the second half forked), without copying the piece's own rows."""
    tp, prof, K = _piece()
    whole = _sample(tp, prof, K, 1)
    H = pipeline.HELD_SAMPLES
    held = pipeline._rows(_sample(tp, prof, K // 3, 1), K // 3 - H, K // 3)
    calls = _split_samples(monkeypatch)
    out = pipeline._sample_piece(tp, tp.pieces[0], prof, PieceTiming.build(prof), 0.0, K // 3, K, 1e-3, workers,
                                 held=held)
    assert calls == ([(K - K // 3) // 2] if workers == 2 else [K - K // 3])
    want = pipeline.concat_samples([held, pipeline._rows(whole, K // 3, K)])
    for col in COLUMNS:
        np.testing.assert_array_equal(getattr(out, col), getattr(want, col), err_msg=col)
    np.testing.assert_array_equal(out.position, whole.position[K // 3 - H :])


#: Motion time of the default windows (``pipeline.lp_window``) against DEFAULT_LP_WINDOW ones, relative: the
#: same receding-horizon optimum over windows of other lengths (18.35 m at 4.63 mm: 193.9609 vs 193.9606 s).
WINDOW_MOTION_RTOL = 1e-4


def test_default_lp_windows_grow_on_long_pieces() -> None:
    """With HiGHS, either method: n_int / LP_WINDOWS_PER_PIECE intervals a window, from DEFAULT_LP_WINDOW up to
    LP_WINDOW_MAX; Clarabel and a given ``lp_window`` as before."""
    m = router()
    long = ex.flower(45).pieces[0]
    for method, knots in (("lp", None), ("lp", 4.63), ("lp+nlp", None), ("lp+nlp", 4.63)):
        plan = pipeline.plan_piece(long, m, Options(method=method, knot_spacing=knots))
        want = min(pipeline.LP_WINDOW_MAX, -(-plan.n_int // pipeline.LP_WINDOWS_PER_PIECE))
        assert want > pipeline.DEFAULT_LP_WINDOW
        assert plan.window == want
        assert pipeline.plan_piece(long, m, Options(method=method, knot_spacing=knots, lp_window=60)).window == max(
            60, 3 * plan.overlap)
    clarabel = pipeline.plan_piece(long, m, Options(method="lp", solver="clarabel"))
    assert clarabel.window == pipeline.DEFAULT_LP_WINDOW
    short = ex.flower(1).pieces[0]
    assert pipeline.plan_piece(short, m, Options(method="lp")).window == pipeline.DEFAULT_LP_WINDOW
    # a piece long enough to grow its windows still has enough of them for two chains
    assert pipeline.LP_WINDOWS_PER_PIECE >= 2 * pipeline.LP_CHAIN_MIN_WINDOWS


def test_grown_lp_windows_hold_the_limits_at_the_same_motion() -> None:
    """Twelve flower loops (2,119 intervals: windows of 265): two chains, the sampled limits hold, and the motion
    is that of 200-interval windows within WINDOW_MOTION_RTOL."""
    tp, m = ex.flower(12), router()
    grown = schedule(tp, m, Options(method="lp", nlp_workers=1))
    plain = schedule(tp, m, Options(method="lp", nlp_workers=1, lp_window=pipeline.DEFAULT_LP_WINDOW))
    assert grown.summary["windows"] < plain.summary["windows"]
    assert grown.summary["lp_chains"] == 1 and grown.summary["lp_seam_fallbacks"] == 0
    _check(tp, m, grown)
    assert grown.summary["motion_time"] == pytest.approx(plain.summary["motion_time"], rel=WINDOW_MOTION_RTOL)
