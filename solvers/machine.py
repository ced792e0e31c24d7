"""Machine model: per-axis kinematic limits and feed-drive model (spec §4, §5, §8).

Drive model per axis (identified on the router, thesis Table 3-1):

    control signal  u = M a + b v + c + d sign(v)      [V]
    servo error     e = Kv v + Ka a + Kj j             [mm]

with v, a, j the axis velocity (mm/s), acceleration (mm/s^2) and jerk
(mm/s^3).  Kinematic LP limits vmax, amax, jmax are either given or derived
from the drive model so that |u| <= umax and |e| <= emax hold (spec §4,
"Deriving V/A/J limits"):

    amax = (umax - b vmax - |c| - d) / M
    if Kv vmax + Ka amax >= emax:  Ka amax = share (emax - Kv vmax)
    jmax = (emax - Kv vmax - Ka amax) / Kj
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from geometry.toolpath import MIN_FEED_MM_S
from solvers.errors import InvalidMachineError

AXES = ("x", "y", "z")
#: Fraction of the servo-error budget left after velocity given to acceleration
#: when velocity + acceleration alone would exhaust it (thesis: about 3/4 on X).
ACCEL_ERROR_SHARE = 0.75
#: When the drive cannot reach the requested vmax, vmax is set so that viscous
#: friction uses this fraction of the voltage left after Coulomb friction and bias.
VOLTAGE_SHARE_FOR_SPEED = 0.5


@dataclass(frozen=True)
class DriveModel:
    """Feed-drive model of one axis.

    Attributes:
        M: V s^2/mm (inertia), b: V s/mm (viscous), c: V (bias, e.g. gravity),
        d: V (Coulomb), Kv: s, Ka: s^2, Kj: s^3 (servo-error coefficients),
        umax: V, emax: mm.
        vmax: mm/s, the drive's own speed limit (motor speed), or None: the NLP
            then limits speed only through u and e.  (``AxisLimits.vmax`` is the
            LP's velocity limit, a conservative proxy, spec §8.)
    """

    M: float
    b: float
    c: float
    d: float
    Kv: float
    Ka: float
    Kj: float
    umax: float
    emax: float
    vmax: float | None = None


@dataclass(frozen=True)
class AxisLimits:
    """Kinematic limits of one axis: vmax mm/s, amax mm/s^2, jmax mm/s^3."""

    vmax: float
    amax: float
    jmax: float


@dataclass(frozen=True)
class Axis:
    name: str
    limits: AxisLimits
    drive: DriveModel | None = None


@dataclass(frozen=True)
class Machine:
    """A 3-axis Cartesian machine.

    Attributes:
        name: preset name or "custom".
        axes: (x, y, z).
        feed_max: optional tangential feed limit, mm/s.
    """

    name: str
    axes: tuple[Axis, Axis, Axis]
    feed_max: float | None = None

    def __post_init__(self) -> None:
        if len(self.axes) != 3:
            raise InvalidMachineError("need exactly 3 axes (x, y, z)", field="machine.axes")
        for ax in self.axes:
            for key in ("vmax", "amax", "jmax"):
                _limit(getattr(ax.limits, key), f"machine.axes.{ax.name}.{key}")
            if ax.drive is not None:
                for key in ("M", "umax", "emax", "Kv", "Kj"):
                    _positive(getattr(ax.drive, key), f"machine.axes.{ax.name}.drive.{key}")
                for key in ("b", "d", "Ka"):
                    v = getattr(ax.drive, key)
                    if not (math.isfinite(v) and v >= 0):
                        raise InvalidMachineError(
                            "must be finite and >= 0", field=f"machine.axes.{ax.name}.drive.{key}", value=v
                        )
                if ax.drive.vmax is not None:
                    _limit(ax.drive.vmax, f"machine.axes.{ax.name}.drive.vmax")
                if not math.isfinite(ax.drive.c):
                    raise InvalidMachineError(
                        "must be finite", field=f"machine.axes.{ax.name}.drive.c", value=ax.drive.c
                    )
        if self.feed_max is not None:
            _limit(self.feed_max, "machine.feed_max")

    def limit_arrays(self) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """Per-axis (vmax, amax, jmax), each (3,) in mm/s, mm/s^2, mm/s^3."""
        return (
            np.array([a.limits.vmax for a in self.axes]),
            np.array([a.limits.amax for a in self.axes]),
            np.array([a.limits.jmax for a in self.axes]),
        )

    def stopping_distance(self, feed: float = math.inf) -> float:
        """Longest distance (mm) any axis needs to stop from vmax under amax, jmax (spec §6); ``feed`` (mm/s), if
        given, caps vmax as ``feed_max`` does (a piece's programmed feed: ``Piece.feed``)."""
        worst = 0.0
        for ax in self.axes:
            v, a, j = ax.limits.vmax, ax.limits.amax, ax.limits.jmax
            v = min(v, feed)
            if self.feed_max is not None:
                v = min(v, self.feed_max)
            D = v / 2.0 * (v / a + a / j) if v >= a * a / j else v * math.sqrt(v / j)
            worst = max(worst, D)
        return worst

    def top_feed(self, feed: float = math.inf) -> float:
        """The fastest any axis may move (mm/s): its vmax, at most the feed cap and ``feed`` (as in
        ``stopping_distance``)."""
        v = min(max(ax.limits.vmax for ax in self.axes), feed)
        return v if self.feed_max is None else min(v, self.feed_max)

    @property
    def has_drives(self) -> bool:
        """Whether every axis has a drive model (needed for control signal and servo error)."""
        return all(a.drive is not None for a in self.axes)

    def drive_arrays(self) -> dict[str, NDArray[np.float64]]:
        """Per-axis drive parameters {M, b, c, d, Kv, Ka, Kj, umax, emax}, each (3,).

        Raises InvalidMachineError if an axis has no drive model.
        """
        missing = [a.name for a in self.axes if a.drive is None]
        if missing:
            raise InvalidMachineError(
                "the drive model is needed (control signal / servo error)", field=f"machine.axes.{missing[0]}.drive"
            )
        keys = ("M", "b", "c", "d", "Kv", "Ka", "Kj", "umax", "emax")
        out = {k: np.array([getattr(a.drive, k) for a in self.axes], dtype=np.float64) for k in keys}
        out["vmax"] = np.array([np.inf if a.drive is None or a.drive.vmax is None else a.drive.vmax
                                for a in self.axes], dtype=np.float64)
        return out

    def with_feed_max(self, feed_max: float | None) -> Machine:
        return replace(self, feed_max=feed_max)


def drive_outputs(
    drives: dict[str, NDArray[np.float64]], v: NDArray[np.float64], a: NDArray[np.float64], j: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Control signal u (V) and servo error e (mm), each (K, 3), from axis v, a, j (K, 3):

        u = M a + b v + c + d sign(v),   e = Kv v + Ka a + Kj j
    """
    u = drives["M"] * a + drives["b"] * v + drives["c"] + drives["d"] * np.sign(v)
    e = drives["Kv"] * v + drives["Ka"] * a + drives["Kj"] * j
    return u, e


def drive_speed_bound(drives: dict[str, NDArray[np.float64]]) -> NDArray[np.float64]:
    """Per-axis speed (mm/s, (3,)) that no motion from rest can pass under |u| <= umax: at the peak of |v| the
    acceleration is 0, so u = b v + c + d sign(v) there, and |v| <= (umax + |c| - d) / b (inf where b = 0, or
    where that is not positive: a drive that cannot move, which ``derive_limits`` refuses, bounds nothing here).
    The servo error bounds nothing of the kind (a falling acceleration's jerk offsets Kv v at the peak)."""
    b = drives["b"]
    volts = drives["umax"] + np.abs(drives["c"]) - drives["d"]
    ok = (b > 0.0) & (volts > 0.0)
    return np.where(ok, volts / np.where(ok, b, 1.0), np.inf)


#: The range of a speed, acceleration or jerk limit and a feed cap (mm/s, mm/s^2, mm/s^3): any machine's fit in it
#: with room (and the random cases' machines scaled down to micrometre paths: bench seed 5029's amax 9.7e-6), and
#: within it the stopping distance v^2 / a, the ramp times a / j and the knots they size stay finite and positive
#: in float64 (session 59's probe: amax 5e-324 read an infinite stopping distance, a 500; feed_max 1e-310 a zero
#: one; 1e-200 was already a typed error).
LIMIT_MIN, LIMIT_MAX = MIN_FEED_MM_S, 1e15  # (the programmed feeds' floor too: one number)
LIMIT_RULE = f"must be a finite number in [{LIMIT_MIN:g}, {LIMIT_MAX:g}]"


def _positive(v: float, fld: str) -> None:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
        raise InvalidMachineError("must be a finite number > 0", field=fld, value=v)


def _limit(v: float, fld: str) -> None:
    """A kinematic limit or feed cap within [LIMIT_MIN, LIMIT_MAX]."""
    _positive(v, fld)
    if not LIMIT_MIN <= v <= LIMIT_MAX:
        raise InvalidMachineError(LIMIT_RULE, field=fld, value=v)


def derive_limits(drive: DriveModel, vmax: float, name: str = "axis") -> AxisLimits:
    """LP limits that keep |u| <= umax and |e| <= emax (spec §4), for a requested vmax.

    If the drive cannot hold ``vmax`` (no voltage left for acceleration, or the
    velocity alone uses the error budget), vmax is lowered so that viscous
    friction uses ``VOLTAGE_SHARE_FOR_SPEED`` of the remaining voltage.
    """
    if drive.vmax is not None:  # (the drive's own speed limit, which lp+nlp holds: the LP's too)
        vmax = min(vmax, drive.vmax)
    volts_left = drive.umax - abs(drive.c) - drive.d
    if volts_left <= 0:
        raise InvalidMachineError(
            f"bias |c| + Coulomb d = {abs(drive.c) + drive.d} V leaves no control signal under umax",
            field=f"machine.axes.{name}.drive.umax",
            value=drive.umax,
        )
    v_cap = VOLTAGE_SHARE_FOR_SPEED * volts_left / drive.b if drive.b > 0 else math.inf
    v_cap = min(v_cap, 0.5 * drive.emax / drive.Kv)
    v = min(vmax, v_cap) if (drive.b * vmax >= volts_left or drive.Kv * vmax >= drive.emax) else vmax
    amax = (volts_left - drive.b * v) / drive.M
    budget = drive.emax - drive.Kv * v
    if drive.Ka * amax >= budget:
        amax = ACCEL_ERROR_SHARE * budget / drive.Ka
    jmax = (budget - drive.Ka * amax) / drive.Kj
    derived = {"vmax": v, "amax": amax, "jmax": jmax}
    if not all(math.isfinite(x) and LIMIT_MIN <= x <= LIMIT_MAX for x in derived.values()):
        raise InvalidMachineError(
            f"the limits derived from this drive model (vmax, amax, jmax) must each be a finite number in "
            f"[{LIMIT_MIN:g}, {LIMIT_MAX:g}]: its parameters are out of scale (e.g. Kv, Kj or emax near 0); give "
            "the axis its limits, or a vmax_request",
            field=f"machine.axes.{name}.drive", value=derived)
    return AxisLimits(vmax=v, amax=amax, jmax=jmax)


# --- the modelled 3-axis router (spec §8) -----------------------------------
ROUTER_DRIVES = {
    "x": DriveModel(M=2.13e-3, b=4.67e-2, c=0.148, d=0.241, Kv=4.49e-5, Ka=1.99e-5, Kj=5.20e-8, umax=10.0, emax=0.02),
    "y": DriveModel(M=1.25e-3, b=3.80e-2, c=0.119, d=0.0131, Kv=8.07e-5, Ka=1.52e-6, Kj=1.80e-8, umax=10.0, emax=0.02),
    "z": DriveModel(M=2.581e-3, b=8.381e-2, c=1.0, d=0.217, Kv=4.49e-5, Ka=1.99e-5, Kj=5.20e-8, umax=10.0, emax=0.02),
}
ROUTER_LIMITS = {
    "x": AxisLimits(vmax=150.0, amax=500.0, jmax=63000.0),
    "y": AxisLimits(vmax=150.0, amax=3340.0, jmax=156000.0),
    "z": derive_limits(ROUTER_DRIVES["z"], 150.0, "z"),
}


def router() -> Machine:
    """The thesis router: X, Y limits from Table 3-4, Z derived from its drive model."""
    return Machine(
        name="router",
        axes=tuple(Axis(n, ROUTER_LIMITS[n], ROUTER_DRIVES[n]) for n in AXES),  # type: ignore[arg-type]
    )


PRESETS = {"router": router}


def preset(name: str) -> Machine:
    try:
        return PRESETS[name]()
    except KeyError:
        raise InvalidMachineError(
            f"unknown machine preset; known: {sorted(PRESETS)}", field="machine", value=name
        ) from None
