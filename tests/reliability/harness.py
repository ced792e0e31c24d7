"""Schedule one random case with one method and check it independently (shared by tests and bench/)."""

from __future__ import annotations

import traceback
from collections.abc import Callable
from dataclasses import dataclass, field

from solvers.pipeline import Options, motion_time_floor, schedule
from tests.reliability import checker, gen

TS = 1e-3
METHODS = ("lp", "lp+nlp")
#: Most time samples a case may have (``Options.max_samples``): above it the schedule refuses with an
#: ``OutputTooLargeError`` before building them (bench seed 3061: 70 M samples, 19.5 h of motion, ran a
#: bench worker out of its 8 GB).  4 x the service's job budget (5 M), and seed 615's 15.3 M fit under it.
MAX_SAMPLES = 20_000_000
#: How a refusal reads in ``Outcome.error`` (the bench counts these apart from failures): by that cap, or by a
#: limit too small for float64 positions at TS to show held (``solvers.errors.ResolutionError``: bench seed 16950,
#: whose x jmax one unit in the last place of its x coordinates reads 2.2 x over as a jerk).
#: Also an LP window found infeasible where ``Options.lp_overlap`` was given under the overlap the machine's
#: stopping distance needs (``pipeline._overlap_hint``: the "+opts" profiles draw overlaps from 3 intervals).
REFUSED = ("solvers.errors.OutputTooLargeError", "solvers.errors.ResolutionError",
           "solvers.errors.InfeasibleError: options.lp_overlap:")


@dataclass
class Outcome:
    seed: int
    method: str
    ok: bool
    violations: list[str] = field(default_factory=list)
    utilisation: dict[str, float] = field(default_factory=dict)
    error: str | None = None
    samples: int = 0
    nlp_fallbacks: int = 0
    #: each NLP fallback's status (``diagnostics.nlp_fallbacks``)
    nlp_fallback_statuses: list[str] = field(default_factory=list)

    def describe(self) -> str:
        what = self.error or "; ".join(self.violations)
        return f"seed {self.seed} method {self.method}: {what}"


def options_for(case: gen.Case, method: str) -> Options:
    """The ``Options`` a run of ``case`` with ``method`` uses: the method, TS (or the case's sample period) and
    MAX_SAMPLES, with the case's options (``gen.random_options``; its knot spacing, a factor, times 0.1 x the
    stopping distance of the run's machine, the product's default spacing; "jerk" for method lp only)."""
    given = dict(case.options)
    if method != "lp":
        given.pop("jerk", None)  # (the jerk stage is off with method lp only: ``Options``)
    if "knot_spacing" in given:
        m = case.lp_machine if method == "lp" else case.machine
        given["knot_spacing"] = float(given["knot_spacing"]) * 0.1 * m.stopping_distance()  # type: ignore[arg-type]
    given.setdefault("sample_period", TS)
    return Options(method=method, max_samples=MAX_SAMPLES, **given)  # type: ignore[arg-type]


def promised(opt: Options) -> dict[str, bool]:
    """What the run promises in its samples (``pipeline._promised``), as ``checker.check``'s switches: lp -> v, a
    and j with the jerk stage; lp+nlp -> u, e, and v with ``nlp_axis_velocity``, v, a, j with ``nlp_kinematic``."""
    if opt.method == "lp":
        return {"kinematic": True, "drive": False, "jerk": opt.jerk, "axis_velocity": False}
    kin = opt.nlp_kinematic
    return {"kinematic": kin, "drive": True, "jerk": True, "axis_velocity": opt.nlp_axis_velocity or kin}


def run(case: gen.Case, method: str, before_check: Callable[[int], None] | None = None,
        before_schedule: Callable[[float], None] | None = None) -> Outcome:
    """Schedule ``case`` with ``method`` (and its options: ``options_for``) and check the samples for what they
    promise (``promised``; default options: lp -> v, a, j; lp+nlp -> u, e).

    ``before_schedule(floor)``, if given, is called with ``motion_time_floor`` (s) before the schedule, and
    ``before_check(samples)`` between the schedule and the check (the bench's time budgets)."""
    m = case.lp_machine if method == "lp" else case.machine
    try:
        opt = options_for(case, method)
        tp = case.toolpath()
        floor = motion_time_floor(tp, m, opt)
        if before_schedule is not None:
            before_schedule(floor)
        sch = schedule(tp, m, opt)
    except Exception as exc:
        tb = traceback.format_exception_only(type(exc), exc)[-1].strip()
        return Outcome(case.seed, method, False, error=f"{tb}")
    smp = sch.samples
    if before_check is not None:
        before_check(int(smp.t.size))
    rep = checker.check(case.segments, gen.limits_of(m), opt.sample_period, smp.t, smp.feed, smp.position,
                        program=case.program, **promised(opt))
    # the bound the schedule refuses by up front must be one: never over the motion it returns
    motion = sch.summary["motion_time"]
    if not floor <= motion:
        rep.violations.append(f"motion_time_floor {floor:.9g} s over the motion time {motion:.9g} s")
    fallbacks = sch.diagnostics.get("nlp_fallbacks", [])
    return Outcome(case.seed, method, rep.ok, rep.violations, rep.utilisation, None,
                   int(smp.t.size), len(fallbacks), [f["status"] for f in fallbacks])
