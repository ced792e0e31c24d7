"""Typed errors of the solvers package (one base, structured fields)."""

from __future__ import annotations

from typing import Any


class ScheduleError(Exception):
    """Base of every solver-side failure.

    Attributes:
        field: input field the failure is attributed to (``options.knot_spacing``,
            ``machine.axes.x.amax``...), or ``None`` for internal failures.
        value: offending value, if any.
        rule: what went wrong, in words.
        window: LP/NLP window index, when the failure is inside one.
        axis: axis name, when one axis is to blame.
        status: solver status string, when a solver reported it.
    """

    def __init__(
        self,
        rule: str,
        *,
        field: str | None = None,
        value: Any = None,
        window: int | None = None,
        axis: str | None = None,
        status: str | None = None,
    ) -> None:
        self.rule = rule
        self.field = field
        self.value = value
        self.window = window
        self.axis = axis
        self.status = status
        where = f"{field}: " if field else ""
        extra = ", ".join(
            f"{k}={v}" for k, v in (("window", window), ("axis", axis), ("status", status)) if v is not None
        )
        got = f" (got {value!r})" if value is not None else ""
        super().__init__(f"{where}{rule}{got}" + (f" [{extra}]" if extra else ""))


class InvalidMachineError(ScheduleError):
    """Machine model or limits that cannot be used (non-positive, NaN, infeasible)."""


class ResolutionError(InvalidMachineError):
    """A limit too small for float64 positions sampled at the sample period to show it held: their rounding alone
    reads a large share of it in the sampled differences (``pipeline._noise_room``)."""


class InvalidOptionsError(ScheduleError):
    """Scheduling options out of range."""


class InfeasibleError(ScheduleError):
    """A window's LP has no feasible feed profile."""


class SolverFailure(ScheduleError):
    """The numerical solver failed (status other than optimal)."""


class LimitViolationError(ScheduleError):
    """The sampled output still exceeds a limit after re-verification: nothing is returned."""


class OutputTooLargeError(ScheduleError):
    """The schedule's time samples would exceed ``Options.max_samples``: raised before they are built."""
