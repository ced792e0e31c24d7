"""Rest-to-rest straight lines: our schedule vs Ruckig's time-optimal jerk-limited trajectory.

Ruckig plans all 3 axes with the per-axis vmax/amax/jmax.  Its default
``Synchronization.Time`` only makes the axes *finish* together; each axis
keeps its own profile shape, so the tool leaves the straight line (measured
below, several mm on long moves).  ``Synchronization.Phase`` scales the axis
profiles to one shape, so the motion stays on the line; that is the peer
used for the gap.  As a cross-check the 1-DoF Ruckig optimum along the line
with the path limits min_i(limit_i / |u_i|) is computed too.

Our runs: default Options (jerk on) and knot_spacing = L/50.  Gap =
(ours - Ruckig phase) / Ruckig phase.  Our 1 kHz positions also go through
tests/fdcheck.utilisation.
"""

from __future__ import annotations

import statistics
import time
from typing import Any

import numpy as np

from bench._common import LIMIT_FACTOR, TS, emit, env_info, gap_pct, limits, row, run_ours, verdict
from geometry import Toolpath
from geometry import examples as ex
from solvers.machine import router
from solvers.pipeline import Options
from tests.fdcheck import utilisation

LENGTHS = (1.0, 5.0, 20.0, 50.0, 100.0, 200.0, 500.0)
DIRECTIONS = {
    "x": (1.0, 0.0, 0.0),
    "xy": (1.0, 1.0, 0.0),
    "xyz": (1.0, 0.3, 0.1),
}
RUCKIG_REPEATS = 5
OURS_REPEATS = 3


def ruckig_line(target: np.ndarray, vmax: np.ndarray, amax: np.ndarray, jmax: np.ndarray,
                sync: str) -> tuple[float, float, float]:
    """(duration s, median calc time s, max distance from the line mm) of a rest-to-rest Ruckig move."""
    from ruckig import InputParameter, Result, Ruckig, Synchronization, Trajectory

    dof = target.size
    otg = Ruckig(dof)
    inp = InputParameter(dof)
    inp.current_position = [0.0] * dof
    inp.current_velocity = [0.0] * dof
    inp.current_acceleration = [0.0] * dof
    inp.target_position = [float(x) for x in target]
    inp.target_velocity = [0.0] * dof
    inp.target_acceleration = [0.0] * dof
    inp.max_velocity = [float(x) for x in vmax]
    inp.max_acceleration = [float(x) for x in amax]
    inp.max_jerk = [float(x) for x in jmax]
    inp.synchronization = getattr(Synchronization, sync)
    traj = Trajectory(dof)
    res = otg.calculate(inp, traj)  # warm-up
    times = []
    for _ in range(RUCKIG_REPEATS):
        traj = Trajectory(dof)
        t0 = time.perf_counter()
        res = otg.calculate(inp, traj)
        times.append(time.perf_counter() - t0)
    if res not in (Result.Working, Result.Finished):
        raise RuntimeError(f"ruckig failed: {res}")
    dev = 0.0
    if dof > 1:
        u = target / np.linalg.norm(target)
        ts = np.linspace(0.0, traj.duration, 1001)
        P = np.array([traj.at_time(float(t))[0] for t in ts])
        dev = float(np.max(np.linalg.norm(P - np.outer(P @ u, u), axis=1)))
    return float(traj.duration), statistics.median(times), dev


def main() -> dict[str, Any]:
    m = router()
    vmax, amax, jmax = limits(m)
    out: dict[str, Any] = {"bench": "ruckig_lines", "env": env_info(), "cases": [], "rows": []}
    gaps: dict[str, list[float]] = {"default": [], "L/50": []}
    worst_util = {"default": 0.0, "L/50": 0.0}
    max_dev_time_sync = 0.0
    max_dev_phase = 0.0
    for dname, d in DIRECTIONS.items():
        u = np.asarray(d) / np.linalg.norm(d)
        for L in LENGTHS:
            target = L * u
            tp = Toolpath([ex.line((0.0, 0.0, 0.0), (float(target[0]), float(target[1]), float(target[2])))])
            t_phase, c_phase, dev_phase = ruckig_line(target, vmax, amax, jmax, "Phase")
            t_time, _, dev_time = ruckig_line(target, vmax, amax, jmax, "Time")
            au = np.abs(u)
            nz = au > 0
            t_1d, _, _ = ruckig_line(np.array([L]), np.array([np.min(vmax[nz] / au[nz])]),
                                     np.array([np.min(amax[nz] / au[nz])]), np.array([np.min(jmax[nz] / au[nz])]),
                                     "Time")
            max_dev_time_sync = max(max_dev_time_sync, dev_time)
            max_dev_phase = max(max_dev_phase, dev_phase)
            case: dict[str, Any] = {
                "direction": dname, "length_mm": L,
                "ruckig": {"phase_duration": t_phase, "phase_calc_time": c_phase, "phase_max_dev_mm": dev_phase,
                           "time_sync_duration": t_time, "time_sync_max_dev_mm": dev_time, "one_dof_duration": t_1d},
                "ours": {},
            }
            for label, knot in (("default", None), ("L/50", L / 50.0)):
                sch, t = run_ours(tp, m, Options(method="lp", knot_spacing=knot), repeats=OURS_REPEATS)
                util = utilisation(sch.samples.position, TS, vmax, amax, jmax)
                mt = sch.summary["motion_time"]
                g = gap_pct(mt, t_phase)
                gaps[label].append(g)
                worst_util[label] = max(worst_util[label], max(util.values()))
                case["ours"][label] = {"motion_time": mt, "gap_pct": g, "compute_time": t["compute_time"],
                                       "knot_spacing": sch.summary["knot_spacing"],
                                       "control_points": sch.summary["control_points"],
                                       "fd_utilisation": util}
            out["cases"].append(case)
            o1, o2 = case["ours"]["default"], case["ours"]["L/50"]
            out["rows"].append(row(
                f"ruckig line {dname} {L:g} mm: motion time (default / knots L/50)",
                f"{o1['motion_time']:.4f} / {o2['motion_time']:.4f} s",
                f"{t_phase:.4f} s (phase sync)",
                f"{o1['gap_pct']:+.1f} % / {o2['gap_pct']:+.1f} %", "—", "info",
            ))
    out["summary"] = {
        "gap_pct_default": {"min": min(gaps["default"]), "median": statistics.median(gaps["default"]),
                            "max": max(gaps["default"])},
        "gap_pct_L50": {"min": min(gaps["L/50"]), "median": statistics.median(gaps["L/50"]), "max": max(gaps["L/50"])},
        "max_fd_utilisation": worst_util,
        "ruckig_time_sync_max_dev_mm": max_dev_time_sync,
        "ruckig_phase_sync_max_dev_mm": max_dev_phase,
        "ruckig_time_sync_same_duration": all(
            abs(c["ruckig"]["phase_duration"] - c["ruckig"]["time_sync_duration"]) < 1e-9 for c in out["cases"]
        ),
        "ruckig_phase_equals_1dof": all(
            abs(c["ruckig"]["phase_duration"] - c["ruckig"]["one_dof_duration"]) < 1e-9 for c in out["cases"]
        ),
    }
    sm = out["summary"]
    for label, key in (("default", "gap_pct_default"), ("L/50", "gap_pct_L50")):
        out["rows"].append(row(
            f"ruckig lines (21 cases): gap summary, knots {label}",
            f"median {sm[key]['median']:+.1f} %", "Ruckig phase-sync optimum",
            f"min {sm[key]['min']:+.1f} %, max {sm[key]['max']:+.1f} %", "—", "info",
        ))
        out["rows"].append(row(
            f"ruckig lines: our peak FD utilisation (any axis/limit), knots {label}",
            f"{worst_util[label]:.4f}", "—", "—", f"<= {LIMIT_FACTOR}", verdict(worst_util[label] <= LIMIT_FACTOR),
        ))
    out["rows"].append(row(
        "ruckig lines: Ruckig off-line deviation, Time vs Phase sync",
        "—", f"Time sync {max_dev_time_sync:.3g} mm, Phase sync {max_dev_phase:.2g} mm", "—", "—", "info",
    ))
    emit(out)
    return out


if __name__ == "__main__":
    main()
