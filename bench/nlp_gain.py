"""LP + NLP (issue 3): gain over LP, cost of windowing, distance to the model's limit, long-path speed and memory.

1. One flower loop, router preset: motion time of method ``lp`` vs ``lp+nlp``
   (target: at least 25 % shorter), the windowed NLP vs one full-horizon NLP
   window at the same knots (target: within 1 %), and vs one full-horizon NLP
   at 4x finer knots (the best schedule this model admits; target: within 2 %).
2. The long path (45 loops, about 18.35 m) at the issue's resolution (4.63 mm
   knots, about 4000 control points), with 1 and 2 NLP worker processes, and
   at the default knot spacing: ``lp`` vs ``lp+nlp`` motion (target: at least
   25 % shorter) and compute / motion of ``lp+nlp`` (target: at most 5 %; wall
   time, with the process's CPU time beside it), per-window LP and NLP times,
   NLP solver iterations (the dense interior point's, ``solvers.ipm``, and Ipopt's for the solves it
   hands over), fallbacks, and the peak memory of a fresh subprocess
   (VmHWM) for 18.35 m and, with ``--long-memory``, 183.5 m.
Every schedule's sampled u and e are recomputed by finite differences
(tests/fdcheck.py) and the worst utilisation is reported.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import time
from typing import Any

import numpy as np

from bench._common import emit, env_info, proc_status_mb, reset_hwm, row, run_module, verdict
from geometry import examples as ex
from solvers.machine import Machine, router
from solvers.pipeline import Options, Schedule, schedule
from tests.fdcheck import fd_drive

LOOPS = 45
GAIN_TARGET = 0.25
WINDOW_TARGET = 0.01
LIMIT_TARGET = 0.02
RATIO_TARGET_PCT = 5.0
#: Knot spacing of the issue's 18.5 m speed target (about 4000 control points), mm.
KNOT_ISSUE = 4.63
#: The near-the-limit target at an explicit finer resolution (``Options.knot_spacing``, one LP
#: window over the loop): the default's gap is the feed spline's resolution, not the windowing.
KNOT_FINE = 0.9


def _drive_util(m: Machine, sch: Schedule) -> dict[str, float]:
    keys = ("M", "b", "c", "d", "Kv", "Ka", "Kj", "umax", "emax")
    dr = {k: np.array([getattr(ax.drive, k) for ax in m.axes]) for k in keys}
    u, e = fd_drive(sch.samples.position, sch.summary["sample_period"], dr)
    return {"u": float(np.max(np.abs(u) / dr["umax"])), "e": float(np.max(np.abs(e) / dr["emax"]))}


def _timed(tp: Any, m: Machine, opts: Options) -> tuple[Schedule, float]:
    t0 = time.perf_counter()
    sch = schedule(tp, m, opts)
    return sch, time.perf_counter() - t0


def one_loop(out: dict[str, Any]) -> None:
    m = router()
    tp = ex.flower(1)
    schedule(tp, m, Options())  # warm-up: imports, first nlpsol builds
    lp, t_lp = _timed(tp, m, Options(method="lp"))
    win, t_win = _timed(tp, m, Options())
    full, t_full = _timed(tp, m, Options(nlp_window=100_000))
    d = win.summary["knot_spacing"]
    fine, t_fine = _timed(tp, m, Options(knot_spacing=d / 4, lp_window=100_000, nlp_window=100_000))
    res = {
        "lp": lp.summary["motion_time"], "lp+nlp": win.summary["motion_time"],
        "full_horizon": full.summary["motion_time"], "full_horizon_4x_finer": fine.summary["motion_time"],
        "compute": {"lp": t_lp, "lp+nlp": t_win, "full": t_full, "fine": t_fine},
        "knot_spacing": d, "nlp_windows": win.summary["nlp_windows"],
        "fd_util": {k: _drive_util(m, s) for k, s in (("lp+nlp", win), ("full", full), ("fine", fine))},
        "fallbacks": len(win.diagnostics["nlp_fallbacks"]),
    }
    out["one_loop"] = res
    gain = 1 - res["lp+nlp"] / res["lp"]
    wcost = res["lp+nlp"] / res["full_horizon"] - 1
    lcost = res["lp+nlp"] / res["full_horizon_4x_finer"] - 1
    u = res["fd_util"]["lp+nlp"]
    out["rows"] += [
        row("1 flower loop: lp+nlp vs lp motion time",
            f"{res['lp+nlp']:.4f} s ({t_win:.2f} s compute, {res['nlp_windows']} NLP windows)",
            f"lp {res['lp']:.4f} s ({t_lp:.2f} s)", f"{100 * gain:.1f} % shorter",
            f">= {100 * GAIN_TARGET:.0f} %", verdict(gain >= GAIN_TARGET)),
        row("1 flower loop: windowed vs one full-horizon NLP (same knots)",
            f"{res['lp+nlp']:.4f} s", f"full {res['full_horizon']:.4f} s ({t_full:.2f} s)",
            f"{100 * wcost:+.2f} %", f"<= {100 * WINDOW_TARGET:.0f} %", verdict(wcost <= WINDOW_TARGET)),
        row(f"1 flower loop: vs full-horizon NLP at 4x finer knots ({d / 4:.3f} mm)",
            f"{res['lp+nlp']:.4f} s", f"fine {res['full_horizon_4x_finer']:.4f} s ({t_fine:.1f} s)",
            f"{100 * lcost:+.2f} %", f"<= {100 * LIMIT_TARGET:.0f} %", verdict(lcost <= LIMIT_TARGET)),
        row("1 flower loop lp+nlp: sampled |u|/umax, |e|/emax (FD of 1 kHz positions)",
            f"u {u['u']:.4f}, e {u['e']:.4f}", "—", "—", "<= 1.01", verdict(max(u.values()) <= 1.01)),
    ]
    # the same target at an explicit finer resolution: the windowed NLP at KNOT_FINE (its NLP windows
    # by default, one LP window over the loop) vs one full-horizon NLP at KNOT_FINE / 4
    fw_opts = Options(knot_spacing=KNOT_FINE, lp_window=100_000)
    schedule(tp, m, fw_opts)  # warm-up: this window shape's nlpsol builds
    fw, t_fw = _timed(tp, m, fw_opts)
    ff, t_ff = _timed(tp, m, Options(knot_spacing=KNOT_FINE / 4, lp_window=100_000, nlp_window=100_000))
    fcost = fw.summary["motion_time"] / ff.summary["motion_time"] - 1
    uf = _drive_util(m, fw)
    res["finer"] = {"knot_spacing": KNOT_FINE, "lp+nlp": fw.summary["motion_time"], "compute": t_fw,
                    "full_horizon_4x_finer": ff.summary["motion_time"], "compute_full": t_ff, "fd_util": uf,
                    "fallbacks": len(fw.diagnostics["nlp_fallbacks"])}
    out["rows"].append(row(
        f"1 flower loop at {KNOT_FINE:g} mm knots (option; one LP window): vs full-horizon NLP at "
        f"{KNOT_FINE / 4:g} mm",
        f"{fw.summary['motion_time']:.4f} s ({t_fw:.2f} s compute; u {uf['u']:.4f}, e {uf['e']:.4f})",
        f"fine {ff.summary['motion_time']:.4f} s ({t_ff:.1f} s)", f"{100 * fcost:+.2f} %",
        f"<= {100 * LIMIT_TARGET:.0f} %", verdict(fcost <= LIMIT_TARGET and max(uf.values()) <= 1.01),
    ))


def child(method: str, loops: int, knot: float | None) -> None:
    """Fresh process: build the path, schedule once, print the scheduling's peak RSS (VmHWM)."""
    tp = ex.flower(loops)
    rss0 = proc_status_mb("VmRSS")
    reset = reset_hwm()
    t0, c0 = time.perf_counter(), _cpu_s()
    sch = schedule(tp, router(), Options(method=method, knot_spacing=knot))
    el, cpu = time.perf_counter() - t0, _cpu_s() - c0
    n = sch.samples.t.size
    s = sch.summary
    print(json.dumps({"loops": loops, "method": method, "knot_spacing": s["knot_spacing"],
                      "compute_time": el, "compute_cpu": cpu, "motion_time": s["motion_time"],
                      "lp_time": s["lp_time"], "nlp_time": s.get("nlp_time"), "nlp_windows": s.get("nlp_windows"),
                      "nlp_iterations": s.get("nlp_iterations"), "nlp_ipm_iterations": s.get("nlp_ipm_iterations"),
                      "nlp_ipm_handed": s.get("nlp_ipm_handed"), "nlp_ipm_infeasible": s.get("nlp_ipm_infeasible"),
                      "nlp_cut_rounds": s.get("nlp_cut_rounds"),
                      "nlp_failures": s.get("nlp_failures"), "load_average": os.getloadavg()[0],
                      "rss_before_mb": rss0, "peak_mb": proc_status_mb("VmHWM") if reset else None,
                      "samples": n, "sample_mb": 8.0 * n * 21 / 2**20}), flush=True)


def run_child(method: str, loops: int, knot: float | None, timeout: float = 3600) -> dict[str, Any]:
    args = ["--child", method, "--loops", str(loops)]
    if knot is not None:
        args += ["--knot", str(knot)]
    return run_module("bench.nlp_gain", args, timeout)


def _cpu_s() -> float:
    """CPU seconds of this process and its reaped children (forked NLP workers): a figure the
    other processes on the machine do not inflate the way they inflate wall time."""
    a, b = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return a.ru_utime + a.ru_stime + b.ru_utime + b.ru_stime


#: (label, knot spacing in mm or None for the default, NLP worker processes or None for the default
#: ``Options.nlp_workers``: this process's cores, at most 2).  The issue states the speed target for
#: "about 4000 control points, 20000 checkpoints" on this 2-core machine: 4.63 mm knots (3965 control
#: points, N = 4 plus knots: ~19,800 checkpoints) with the default options; 1 worker is what the service
#: gives each job (it runs one job per core).  The default knots (2.31 mm) halve the spacing for a ~7 %
#: shorter motion.
LONG_CONFIGS: tuple[tuple[str, float | None, int | None], ...] = (
    ("4.63 mm knots (issue: ~4000 cp), default options", KNOT_ISSUE, None),
    ("4.63 mm knots, 1 NLP worker (a service job)", KNOT_ISSUE, 1),
    ("default knots, default options", None, None),
)


def long_path(out: dict[str, Any], long_memory: bool) -> None:
    m = router()
    tp = ex.flower(LOOPS)
    schedule(ex.flower(1), m, Options())
    schedule(ex.flower(1), m, Options(knot_spacing=KNOT_ISSUE))
    what = f"long path {tp.length / 1000:.2f} m"
    out["long"] = {"path_length": tp.length, "runs": []}
    for label, knot, workers in LONG_CONFIGS:
        lp, t_lp = _timed(tp, m, Options(method="lp", knot_spacing=knot))
        c0 = _cpu_s()
        opts = Options(knot_spacing=knot) if workers is None else Options(knot_spacing=knot, nlp_workers=workers)
        nl, t_nl = _timed(tp, m, opts)
        cpu = _cpu_s() - c0
        s = nl.summary
        res = {
            "label": label, "knot_spacing": s["knot_spacing"], "nlp_workers": opts.nlp_workers,
            "lp_motion": lp.summary["motion_time"], "lp_compute": t_lp,
            "nlp_motion": s["motion_time"], "nlp_compute": t_nl, "nlp_compute_cpu": cpu,
            "lp_stage_time": s["lp_time"],
            "nlp_stage_time": s["nlp_time"], "lp_windows": s["windows"], "nlp_windows": s["nlp_windows"],
            "nlp_iterations": s["nlp_iterations"], "nlp_ipm_iterations": s["nlp_ipm_iterations"],
            "nlp_ipm_handed": s["nlp_ipm_handed"], "nlp_ipm_infeasible": s["nlp_ipm_infeasible"],
            "nlp_cut_rounds": s["nlp_cut_rounds"],
            "fallbacks": nl.diagnostics["nlp_fallbacks"], "control_points": s["control_points"],
            "checkpoints": s["checkpoints"], "sample_repairs": s["sample_repairs"],
            "lp_window_ms": {"median": 1e3 * statistics.median(s["window_times"]),
                             "max": 1e3 * max(s["window_times"])},
            "nlp_window_ms": {"median": 1e3 * statistics.median(s["nlp_window_times"]),
                              "max": 1e3 * max(s["nlp_window_times"])},
            "fd_util": _drive_util(m, nl),
            "load_average": os.getloadavg()[0],
        }
        del lp, nl
        out["long"]["runs"].append(res)
        gain = 1 - res["nlp_motion"] / res["lp_motion"]
        ratio = 100 * t_nl / res["nlp_motion"]
        tag = f"{what}, {label}"
        out["rows"] += [
            row(f"{tag}: lp+nlp vs lp motion time", f"{res['nlp_motion']:.2f} s", f"lp {res['lp_motion']:.2f} s",
                f"{100 * gain:.1f} % shorter", f">= {100 * GAIN_TARGET:.0f} %", verdict(gain >= GAIN_TARGET)),
            row(f"{tag}: lp+nlp compute / motion ({res['control_points']} cp, {res['checkpoints']} checkpoints; "
                f"load average {res['load_average']:.1f})",
                f"{t_nl:.1f} s / {res['nlp_motion']:.1f} s (LP {res['lp_stage_time']:.1f} s, NLP "
                f"{res['nlp_stage_time']:.1f} s; CPU {cpu:.1f} s)", "—", f"{ratio:.1f} %",
                f"<= {RATIO_TARGET_PCT:g} %", verdict(ratio <= RATIO_TARGET_PCT)),
            row(f"{tag}: windows, per-window times, NLP iterations (dense IPM's; solves handed to Ipopt or found "
                "infeasible by it), fallbacks",
                f"{res['lp_windows']} LP windows (median {res['lp_window_ms']['median']:.0f} ms), "
                f"{res['nlp_windows']} NLP windows (median {res['nlp_window_ms']['median']:.0f} ms, max "
                f"{res['nlp_window_ms']['max']:.0f} ms), {res['nlp_iterations']} it ({res['nlp_ipm_iterations']} "
                f"dense; {res['nlp_ipm_handed']} solves handed to Ipopt, {res['nlp_ipm_infeasible']} found "
                f"infeasible), "
                f"{res['nlp_cut_rounds']} tightening rounds, {len(res['fallbacks'])} fallbacks",
                "—", "—", "—", "info"),
            row(f"{tag}: sampled |u|/umax, |e|/emax", f"u {res['fd_util']['u']:.4f}, e {res['fd_util']['e']:.4f}",
                "—", "—", "<= 1.01", verdict(max(res["fd_util"].values()) <= 1.01)),
        ]
    out["long"]["memory"] = {"18m": run_child("lp+nlp", LOOPS, KNOT_ISSUE)}
    if long_memory:
        out["long"]["memory"]["183m"] = run_child("lp+nlp", 10 * LOOPS, KNOT_ISSUE)
    for key, mem in out["long"]["memory"].items():
        if "peak_mb" in mem:
            out["rows"].append(row(
                f"peak memory, lp+nlp, {key} path, 4.63 mm knots (fresh process, VmHWM)",
                f"{mem['peak_mb']:.0f} MB (RSS before {mem['rss_before_mb']:.0f} MB; samples "
                f"{mem['samples']} x 21 columns = {mem['sample_mb']:.0f} MB)", "—", "—", "bounded", "info"))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--child", default=None)
    ap.add_argument("--loops", type=int, default=LOOPS)
    ap.add_argument("--knot", type=float, default=None)
    ap.add_argument("--long-memory", action="store_true", help="also run the 183.5 m path (slow)")
    ap.add_argument("--skip-long", action="store_true")
    a = ap.parse_args()
    if a.child is not None:
        child(a.child, a.loops, a.knot)
        return
    out: dict[str, Any] = {"bench": "nlp_gain", "env": env_info(), "rows": []}
    one_loop(out)
    if not a.skip_long:
        long_path(out, a.long_memory)
    emit(out)


if __name__ == "__main__":
    main()
