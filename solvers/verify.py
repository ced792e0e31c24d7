r"""Last line of defence: the sampled output re-checked against every enforced limit.

The LP and NLP hold their limits at checkpoints and verify them on a finer
grid (4 points per checkpoint gap and both sides of every geometry knot), but
a curvature peak narrower than that grid can still sit between two
verification points (random case 63: |x_ss| peaks over 0.3 mm against a
0.22 mm grid and the sampled acceleration reached 1.085 x amax, with no
unverified point reported).  So the time samples themselves are checked, in
two ways, per sample k and axis i:

- analytic: the v, a, j (and u, e) the pipeline emits at sample k, over their limits;
- finite differences of the emitted positions, as a machine (or an independent
  checker) sees them, with ``REST_PAD`` samples of rest before and after:

      v_k = (x_k - x_{k-1}) / Ts,  a_k = (x_{k+1} - 2 x_k + x_{k-1}) / Ts^2,
      j_k = (x_{k+2} - 3 x_{k+1} + 3 x_k - x_{k-1}) / Ts^3,
      u = M a + b v + c + d sign(v),  e = Kv v + Ka a + Kj j   (central v, j).

Samples over ``1 + REPAIR_TOL`` (analytic) or ``1 + FD_REPAIR_TOL`` (finite
differences) give their arc lengths to the pipeline, which adds them to the
verification grid of their piece and solves that piece again; whatever is
still over ``1 + FAIL_TOL`` after the last round is a ``LimitViolationError``:
the schedule is never returned over its limits silently.

Units: mm, s; utilisations are dimensionless (1.0 = at the limit).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: Analytic utilisation above 1 + this at a sample sends its s back to the solver (the solvers' own
#: verification tolerance).
REPAIR_TOL = 2e-3
#: Finite-difference utilisation above 1 + this sends its s back (differences of a curve at the
#: limit overshoot it by O(Ts^2) terms).
FD_REPAIR_TOL = 5e-3
#: Utilisation above 1 + this after the last repair round is an error (the product's guarantee:
#: every sampled quantity within 1.01 x its limit).
FAIL_TOL = 1e-2
#: Samples of rest padded before and after the motion for the differences.
REST_PAD = 2


@dataclass(frozen=True)
class Limits:
    """The limits a schedule promises, (3,) per axis; None where not enforced.

    vmax, amax, jmax: mm/s, mm/s^2, mm/s^3; umax (V) and emax (mm) with the drive
    coefficients ``drive`` (keys M b c d Kv Ka Kj, each (3,)); feed_cap (K,) mm/s per sample.
    """

    vmax: FloatArray | None
    amax: FloatArray | None
    jmax: FloatArray | None
    drive: dict[str, FloatArray] | None
    feed_cap: FloatArray | None


@dataclass(frozen=True)
class SampleCheck:
    """``repair``: (K,) samples whose s should be verified by the solvers;
    ``worst``: (kind, axis, utilisation, sample index) of the largest utilisation."""

    repair: BoolArray
    worst: tuple[str, str, float, int]

    @property
    def failed(self) -> bool:
        return self.worst[2] > 1.0 + FAIL_TOL


def _fd(position: FloatArray, Ts: float) -> tuple[FloatArray, FloatArray, FloatArray]:
    """v, a, j at every sample k (K, 3): backward v, central a, the third difference over k-1..k+2."""
    p = np.concatenate([np.repeat(position[:1], REST_PAD, axis=0), position,
                        np.repeat(position[-1:], REST_PAD, axis=0)])
    K = position.shape[0]
    k = np.arange(K) + REST_PAD  # padded index of sample k
    v = (p[k] - p[k - 1]) / Ts
    a = (p[k + 1] - 2.0 * p[k] + p[k - 1]) / Ts**2
    j = (p[k + 2] - 3.0 * p[k + 1] + 3.0 * p[k] - p[k - 1]) / Ts**3
    return v, a, j


def _drive(dr: dict[str, FloatArray], v: FloatArray, a: FloatArray, j: FloatArray) -> tuple[FloatArray, FloatArray]:
    """u = M a + b v + c + d sign(v) (V) and e = Kv v + Ka a + Kj j (mm), each (K, 3)."""
    u = dr["M"] * a + dr["b"] * v + dr["c"] + dr["d"] * np.sign(v)
    e = dr["Kv"] * v + dr["Ka"] * a + dr["Kj"] * j
    return u, e


def check(
    Ts: float, position: FloatArray, feed: FloatArray, v: FloatArray, a: FloatArray, j: FloatArray, lim: Limits
) -> SampleCheck:
    """Utilisation of every enforced limit at every sample, analytic and by finite differences."""
    K = position.shape[0]
    v_fd, a_fd, j_fd = _fd(position, Ts)
    # central velocity and jerk for the drive model (as the checker and a drive see them)
    v_c = 0.5 * (v_fd + np.concatenate([v_fd[1:], np.zeros((1, 3))]))
    j_c = 0.5 * (j_fd + np.concatenate([np.zeros((1, 3)), j_fd[:-1]]))
    per: list[tuple[str, FloatArray, FloatArray, FloatArray]] = []  # kind, analytic, fd, limit
    if lim.vmax is not None:
        per.append(("velocity", v, v_fd, lim.vmax))
    if lim.amax is not None:
        per.append(("acceleration", a, a_fd, lim.amax))
    if lim.jmax is not None:
        per.append(("jerk", j, j_fd, lim.jmax))
    if lim.drive is not None:
        dr = lim.drive
        u_an, e_an = _drive(dr, v, a, j)
        u_fd, e_fd = _drive(dr, v_c, a_fd, j_c)
        per.append(("control_signal", u_an, u_fd, dr["umax"]))
        per.append(("servo_error", e_an, e_fd, dr["emax"]))
    repair = np.zeros(K, dtype=bool)
    worst: tuple[str, str, float, int] = ("none", "", 0.0, 0)
    for kind, an, fd, limit in per:
        ua = np.abs(an) / limit
        uf = np.abs(fd) / limit
        repair |= np.any(ua > 1.0 + REPAIR_TOL, axis=1) | np.any(uf > 1.0 + FD_REPAIR_TOL, axis=1)
        both = np.maximum(ua, uf)
        k2, i2 = np.unravel_index(int(np.argmax(both)), both.shape)
        if both[k2, i2] > worst[2]:
            worst = (kind, "xyz"[int(i2)], float(both[k2, i2]), int(k2))
    if lim.feed_cap is not None:
        with np.errstate(divide="ignore", invalid="ignore"):
            uf_ = np.where(np.isfinite(lim.feed_cap), feed / lim.feed_cap, 0.0)
        repair |= uf_ > 1.0 + REPAIR_TOL
        k = int(np.argmax(uf_))
        if uf_[k] > worst[2]:
            worst = ("feed", "", float(uf_[k]), k)
    # a difference spans neighbouring samples: send those back too
    out = repair.copy()
    out[1:] |= repair[:-1]
    out[:-1] |= repair[1:]
    return SampleCheck(out, worst)
