"""Flower loop, velocity + acceleration only: our LP vs toppra (TOPP-RA).

(a) Speed: our compute time (total and LP part) vs toppra with as many grid
    points as our constraint checkpoints, at the default knot spacing and at
    1.0 mm and 0.5 mm.  toppra's timing covers constraint setup, the TOPPRA
    instance and compute_trajectory(0, 0); its geometric path (a cubic
    SplineInterpolator over dense samples of the same NURBS in arc length) is
    built once, outside the timing.  Our compute_time includes geometry
    evaluation and the 1 kHz time reconstruction; lp_time is the LP windows only.
(b) Optimality: our motion time at 1.0 and 0.5 mm vs toppra at 4000 grid points.
(c) Alternated CPU at the default knots (``time.process_time``, medians of ALT_REPEATS, the three runs
    taken in turn so all see the same machine): ours (``schedule()``) vs toppra's solve as in (a), and vs
    toppra like for like: from the same NURBS to 1 kHz axis samples, i.e. (a) plus its path (the NURBS's
    positions at SPLINE_SAMPLES arc lengths and the SplineInterpolator over them) and the 1 kHz
    position, velocity and acceleration of its trajectory.  Our schedule also verifies the limits on an
    8x finer grid and returns jerk, control signal and servo error per sample; toppra does neither.

Both also go through tests/fdcheck.utilisation on 1 kHz positions (v, a only).
"""

from __future__ import annotations

import logging
import statistics
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from bench._common import (
    LIMIT_FACTOR,
    TS,
    emit,
    env_info,
    gap_pct,
    limits,
    repeat,
    row,
    run_ours,
    summary_subset,
    verdict,
)
from geometry import examples as ex
from solvers.machine import router
from solvers.pipeline import Options, schedule
from tests.fdcheck import utilisation

#: Dense samples of the geometry for toppra's spline path.
SPLINE_SAMPLES = 8001
#: toppra grid for the optimality reference (issue 2).
REF_GRID = 4000
#: Optimality target: within 1 % of toppra at 4000 grid points (tests/solvers/test_optimality.py).
GAP_TARGET_PCT = 1.0
KNOTS: tuple[float | None, ...] = (None, 1.0, 0.5)
#: Runs per side in the alternated CPU comparison (c).
ALT_REPEATS = 15


def _toppra_setup() -> tuple[Any, Any, Any]:
    import toppra as ta
    import toppra.algorithm as algo
    import toppra.constraint as constraint

    ta.setup_logging("WARNING")
    logging.getLogger("toppra").setLevel(logging.WARNING)
    return ta, algo, constraint


def toppra_run(path: Any, vmax: np.ndarray, amax: np.ndarray, n_grid: int, length: float,
               parametrizer: str | None = None) -> Any:
    """Constraint setup + TOPPRA + compute_trajectory(0, 0); returns the trajectory."""
    _, algo, constraint = _toppra_setup()
    cons = [
        constraint.JointVelocityConstraint(np.column_stack([-vmax, vmax])),
        constraint.JointAccelerationConstraint(np.column_stack([-amax, amax])),
    ]
    inst = algo.TOPPRA(cons, path, gridpoints=np.linspace(0.0, length, n_grid), parametrizer=parametrizer)
    traj = inst.compute_trajectory(0, 0)
    if traj is None:
        raise RuntimeError(f"toppra failed at {n_grid} grid points")
    return traj


def toppra_like_for_like(tp: Any, vmax: np.ndarray, amax: np.ndarray, n_grid: int) -> Any:
    """toppra from the NURBS to 1 kHz axis samples: its spline path over SPLINE_SAMPLES positions of ``tp``,
    ``toppra_run``, then position, velocity and acceleration at 1 kHz; returns the trajectory."""
    ta, _, _ = _toppra_setup()
    s_dense = np.linspace(0.0, tp.length, SPLINE_SAMPLES)
    path = ta.SplineInterpolator(s_dense, tp.positions(s_dense))
    traj = toppra_run(path, vmax, amax, n_grid, tp.length)
    t = np.arange(0.0, traj.duration, TS)
    for order in range(3):
        traj(t, order)
    return traj


def alternated(tp: Any, m: Any, path: Any, vmax: np.ndarray, amax: np.ndarray, n_grid: int,
               repeats: int = ALT_REPEATS) -> dict[str, Any]:
    """CPU medians (s) of ours, toppra's solve and toppra like for like, taken in turn (c)."""
    runs: dict[str, Callable[[], Any]] = {
        "ours": lambda: schedule(tp, m, Options(method="lp", jerk=False)),
        "toppra_solve": lambda: toppra_run(path, vmax, amax, n_grid, tp.length),
        "toppra_like_for_like": lambda: toppra_like_for_like(tp, vmax, amax, n_grid),
    }
    cpu: dict[str, list[float]] = {k: [] for k in runs}
    for i in range(repeats + 1):
        for k, fn in runs.items():
            t0 = time.process_time()
            fn()
            if i:  # the first round warms up
                cpu[k].append(time.process_time() - t0)
    med = {k: statistics.median(v) for k, v in cpu.items()}
    return {"cpu_median": med, "cpu": cpu, "repeats": repeats, "grid_points": n_grid,
            "ratio_over_toppra_solve": med["ours"] / med["toppra_solve"],
            "ratio_over_toppra_like_for_like": med["ours"] / med["toppra_like_for_like"]}


def _traj_utilisation(traj: Any, vmax: np.ndarray, amax: np.ndarray, jmax: np.ndarray) -> dict[str, float]:
    t = np.arange(0.0, traj.duration, TS)
    t = np.append(t, traj.duration)
    return utilisation(np.asarray(traj(t)), TS, vmax, amax, jmax)


def _va(u: dict[str, float]) -> float:
    return max(v for k, v in u.items() if k[0] in "va")


def main() -> dict[str, Any]:
    ta, _, _ = _toppra_setup()
    tp = ex.flower(1)
    m = router()
    vmax, amax, jmax = limits(m)
    L = tp.length
    s_dense = np.linspace(0.0, L, SPLINE_SAMPLES)
    path = ta.SplineInterpolator(s_dense, tp.evaluate(s_dense).position)

    out: dict[str, Any] = {"bench": "toppra_vel_acc", "path": "flower(1)", "path_length_mm": L,
                           "toppra_spline_samples": SPLINE_SAMPLES, "env": env_info(), "speed": [], "rows": []}
    ours_by_knot: dict[str, Any] = {}
    for knot in KNOTS:
        label = "default" if knot is None else f"{knot:g}"
        sch, t = run_ours(tp, m, Options(method="lp", jerk=False, knot_spacing=knot))
        n = int(sch.summary["checkpoints"])
        t_tp, times_tp, traj = repeat(lambda n=n: toppra_run(path, vmax, amax, n, L))
        u_ours = utilisation(sch.samples.position, TS, vmax, amax, jmax)
        rec = {
            "knot_spacing_option": label,
            "ours": {**summary_subset(sch), **t, "fd_utilisation": u_ours},
            "toppra": {"grid_points": n, "time": t_tp, "times": times_tp, "duration": traj.duration},
            "ratio_compute_over_toppra": t["compute_time"] / t_tp,
            "ratio_lp_over_toppra": t["lp_time"] / t_tp,
        }
        out["speed"].append(rec)
        ours_by_knot[label] = rec
        out["rows"].append(row(
            f"toppra v/a flower: compute time, knots {label} ({sch.summary['knot_spacing']:.3g} mm), "
            f"{n} checkpoints = toppra grid",
            f"{t['compute_time'] * 1e3:.1f} ms total / {t['lp_time'] * 1e3:.1f} ms LP",
            f"{t_tp * 1e3:.1f} ms",
            f"{rec['ratio_compute_over_toppra']:.2f}x / {rec['ratio_lp_over_toppra']:.2f}x (ours/toppra)",
            "—", "info",
        ))

    # (c) alternated CPU, default knots
    alt = alternated(tp, m, path, vmax, amax, int(ours_by_knot["default"]["toppra"]["grid_points"]))
    out["alternated"] = alt
    med = alt["cpu_median"]
    out["rows"].append(row(
        f"toppra v/a flower: CPU alternated ({alt['repeats']} each, default knots, {alt['grid_points']} grid points), "
        "ours vs toppra's solve / toppra like for like (NURBS in, 1 kHz axis samples out)",
        f"{med['ours'] * 1e3:.1f} ms",
        f"{med['toppra_solve'] * 1e3:.1f} ms / {med['toppra_like_for_like'] * 1e3:.1f} ms",
        f"{alt['ratio_over_toppra_solve']:.2f}x / {alt['ratio_over_toppra_like_for_like']:.2f}x (ours/toppra)",
        "not slower", verdict(alt["ratio_over_toppra_solve"] <= 1.0),
    ))

    # (b) optimality vs toppra at REF_GRID
    t_ref, times_ref, traj_ref = repeat(lambda: toppra_run(path, vmax, amax, REF_GRID, L))
    traj_ca = toppra_run(path, vmax, amax, REF_GRID, L, parametrizer="ParametrizeConstAccel")
    u_ref = _traj_utilisation(traj_ref, vmax, amax, jmax)
    out["toppra_ref"] = {"grid_points": REF_GRID, "time": t_ref, "times": times_ref,
                         "duration": traj_ref.duration, "duration_const_accel": traj_ca.duration,
                         "fd_utilisation": u_ref}
    out["optimality"] = []
    for label in ("1", "0.5", "default"):
        rec = ours_by_knot[label]
        mt = rec["ours"]["motion_time"]
        g = gap_pct(mt, traj_ref.duration)
        out["optimality"].append({"knot_spacing_option": label, "ours_motion_time": mt, "gap_pct": g})
        ok = None if label == "default" else g <= GAP_TARGET_PCT
        out["rows"].append(row(
            f"toppra v/a flower: motion time, ours knots {label} vs toppra {REF_GRID} grid",
            f"{mt:.4f} s", f"{traj_ref.duration:.4f} s", f"{g:+.2f} %",
            f"<= +{GAP_TARGET_PCT:g} %" if ok is not None else "—", verdict(ok),
        ))
    for label in ("1", "0.5"):
        u = ours_by_knot[label]["ours"]["fd_utilisation"]
        worst = _va(u)
        out["rows"].append(row(
            f"toppra v/a flower: our peak v/a utilisation (FD, 1 kHz), knots {label}",
            f"{worst:.4f}", f"toppra {REF_GRID}: {_va(u_ref):.4f}", "—",
            f"<= {LIMIT_FACTOR}", verdict(worst <= LIMIT_FACTOR),
        ))
    emit(out)
    return out


if __name__ == "__main__":
    main()
