"""Independent limit checker: finite differences of sampled positions only.

Shares no code with the solvers: it sees positions at a fixed period, holds
the machine at rest before the first and after the last sample (as a
controller would), and differences them.  A k-th finite difference is a
positive-kernel average of the k-th derivative, so it never over-reports.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
REST_PAD = 4


def fd_kinematics(position: FloatArray, Ts: float) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Velocity, acceleration and jerk (K', 3) by finite differences, rest-padded."""
    p = np.concatenate(
        [np.repeat(position[:1], REST_PAD, axis=0), position, np.repeat(position[-1:], REST_PAD, axis=0)]
    )
    v = np.diff(p, axis=0) / Ts
    a = np.diff(p, n=2, axis=0) / Ts**2
    j = np.diff(p, n=3, axis=0) / Ts**3
    return v, a, j


def utilisation(
    position: FloatArray, Ts: float, vmax: FloatArray, amax: FloatArray, jmax: FloatArray
) -> dict[str, float]:
    v, a, j = fd_kinematics(position, Ts)
    out: dict[str, float] = {}
    for i, ax in enumerate("xyz"):
        out[f"v{ax}"] = float(np.max(np.abs(v[:, i])) / vmax[i])
        out[f"a{ax}"] = float(np.max(np.abs(a[:, i])) / amax[i])
        out[f"j{ax}"] = float(np.max(np.abs(j[:, i])) / jmax[i])
    return out


def fd_drive(position: FloatArray, Ts: float, drive: dict[str, FloatArray],
             kinematics: tuple[FloatArray, FloatArray, FloatArray] | None = None) -> tuple[FloatArray, FloatArray]:
    """Control signal u and servo error e (K'', 3) from finite differences of the positions.

    At each interior point: central velocity (mean of the two adjacent first
    differences), the second difference, and the mean of the two adjacent
    third differences; then u = M a + b v + c + d sign(v), e = Kv v + Ka a + Kj j.
    ``kinematics``: ``fd_kinematics(position, Ts)`` if already at hand (a second copy of the three (K, 3)
    differences is 0.7 GB at cam-bench seed 100's 10.4 M samples, checked under the bench's 8 GiB).
    """
    v, a, j = fd_kinematics(position, Ts) if kinematics is None else kinematics
    L = a.shape[0] + 2  # padded point count
    vc = 0.5 * (v[1 : L - 3] + v[2 : L - 2])
    ac = a[1 : L - 3]
    jc = 0.5 * (j[0 : L - 4] + j[1 : L - 3])
    u = drive["M"] * ac + drive["b"] * vc + drive["c"] + drive["d"] * np.sign(vc)
    e = drive["Kv"] * vc + drive["Ka"] * ac + drive["Kj"] * jc
    return u, e
