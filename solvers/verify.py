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

from solvers.machine import drive_outputs

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: Analytic utilisation above 1 + this at a sample sends its s back to the solver.  Not the
#: solvers' own 0.2 % verification tolerance: between their verification points a bound that is
#: active anyway reaches 1.003-1.005 x (flower, v+a only), within the promise, and repairing that
#: re-solved most long paths twice (18.35 m: 22 -> 65 LP windows).
REPAIR_TOL = 5e-3
#: Finite-difference utilisation above 1 + this sends its s back (differences of a curve at the
#: limit overshoot it by O(Ts^2) terms).
FD_REPAIR_TOL = 5e-3
#: Utilisation above 1 + this after the last repair round is an error (the product's guarantee:
#: every sampled quantity within 1.01 x its limit).
FAIL_TOL = 1e-2
#: Samples of rest padded before and after the motion for the differences.
REST_PAD = 2
#: Samples checked per chunk (bounds the transient arrays: ~20 of (CHUNK, 3) float64).
CHUNK = 65_536


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


def _fd(p: FloatArray, k: NDArray[np.int64], Ts: float) -> tuple[FloatArray, ...]:
    """At padded indices k of the rest-padded positions p: backward v, central a, the third
    difference over k-1..k+2, and for the drive model the central v and j (each (len(k), 3))."""
    v = (p[k] - p[k - 1]) / Ts
    v_next = (p[k + 1] - p[k]) / Ts
    a = (p[k + 1] - 2.0 * p[k] + p[k - 1]) / Ts**2
    j = (p[k + 2] - 3.0 * p[k + 1] + 3.0 * p[k] - p[k - 1]) / Ts**3
    j_prev = (p[k + 1] - 3.0 * p[k] + 3.0 * p[k - 1] - p[k - 2]) / Ts**3
    return v, a, j, 0.5 * (v + v_next), 0.5 * (j + j_prev)


def check(
    Ts: float, position: FloatArray, feed: FloatArray, v: FloatArray, a: FloatArray, j: FloatArray, lim: Limits
) -> SampleCheck:
    """Utilisation of every enforced limit at every sample, analytic and by finite differences
    (in chunks of CHUNK samples, so the transient arrays stay bounded on long paths)."""
    K = position.shape[0]
    p = np.concatenate([np.repeat(position[:1], REST_PAD, axis=0), position,
                        np.repeat(position[-1:], REST_PAD, axis=0)])
    repair = np.zeros(K, dtype=bool)
    worst: tuple[str, str, float, int] = ("none", "", 0.0, 0)
    for c0 in range(0, K, CHUNK):
        c1 = min(K, c0 + CHUNK)
        sl = slice(c0, c1)
        v_fd, a_fd, j_fd, v_c, j_c = _fd(p, np.arange(c0, c1) + REST_PAD, Ts)
        per: list[tuple[str, FloatArray, FloatArray, FloatArray]] = []  # kind, analytic, fd, limit
        if lim.vmax is not None:
            per.append(("velocity", v[sl], v_fd, lim.vmax))
        if lim.amax is not None:
            per.append(("acceleration", a[sl], a_fd, lim.amax))
        if lim.jmax is not None:
            per.append(("jerk", j[sl], j_fd, lim.jmax))
        if lim.drive is not None:
            dr = lim.drive
            u_an, e_an = drive_outputs(dr, v[sl], a[sl], j[sl])
            u_fd, e_fd = drive_outputs(dr, v_c, a_fd, j_c)
            per.append(("control_signal", u_an, u_fd, dr["umax"]))
            per.append(("servo_error", e_an, e_fd, dr["emax"]))
        for kind, an, fd, limit in per:
            ua = np.abs(an) / limit
            uf = np.abs(fd) / limit
            repair[sl] |= np.any(ua > 1.0 + REPAIR_TOL, axis=1) | np.any(uf > 1.0 + FD_REPAIR_TOL, axis=1)
            both = np.maximum(ua, uf)
            k2, i2 = np.unravel_index(int(np.argmax(both)), both.shape)
            if both[k2, i2] > worst[2]:
                worst = (kind, "xyz"[int(i2)], float(both[k2, i2]), c0 + int(k2))
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
