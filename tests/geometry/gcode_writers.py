"""Write a NURBS as Fanuc G06.2, Siemens BSPLINE and LinuxCNC G5.2 text (for round-trip tests).

Numbers are written with numpy's shortest positional repr, which parses back to the
same float64, so a round trip is exact up to the reader's own arithmetic.
"""

from __future__ import annotations

import numpy as np

from geometry.nurbs import NurbsSegment


def num(v: float) -> str:
    """Shortest decimal (no exponent) that parses back to exactly ``v``."""
    return np.format_float_positional(float(v), unique=True, trim="-")


def xyz(p: np.ndarray) -> str:
    return f"X{num(p[0])} Y{num(p[1])} Z{num(p[2])}"


def fanuc(seg: NurbsSegment, feed_mm_min: float = 1200.0) -> str:
    """G06.2 P(rank) with one knot per control-point block and rank knot-only blocks."""
    P, w, U = seg.control_points, seg.weights, seg.knots
    rank = seg.degree + 1
    n = P.shape[0]
    lines = [
        "G21 G90 G17 G94",
        f"G00 {xyz(P[0])}",
        f"G06.2 P{rank} K{num(U[0])} {xyz(P[0])} R{num(w[0])} F{num(feed_mm_min)}",
    ]
    lines += [f"K{num(U[i])} {xyz(P[i])} R{num(w[i])}" for i in range(1, n)]
    lines += [f"K{num(U[i])}" for i in range(n, n + rank)]
    lines.append("G00 X0 Y0 Z0")
    return "\n".join(lines) + "\n"


def siemens(seg: NurbsSegment, feed_mm_min: float = 1200.0, write_pl: bool = True) -> str:
    """BSPLINE SD=p; the start point is P_0 (its weight must be 1); PL on P_1 .. P_{n-p}."""
    P, w, U = seg.control_points, seg.weights, seg.knots
    p = seg.degree
    n = P.shape[0]
    if w[0] != 1.0:
        raise ValueError("Siemens B splines start with weight 1: normalise the weights first")
    lines = ["G21 G90 G17 G94", f"G00 {xyz(P[0])}", f"G01 F{num(feed_mm_min)}", f"BSPLINE SD={p}"]
    for j in range(1, n):
        text = f"{xyz(P[j])} PW={num(w[j])}"
        if write_pl and j <= n - p:
            text += f" PL={num(U[p + j] - U[p + j - 1])}"
        lines.append(text)
    lines.append("G00 X0 Y0 Z0")
    return "\n".join(lines) + "\n"


def linuxcnc(seg: NurbsSegment, feed_mm_min: float = 1200.0) -> str:
    """G5.2 L(order) with the first weight on the G5.2 block, control points X Y P, G5.3."""
    P, w = seg.control_points, seg.weights
    lines = [
        "G21 G90 G17 G94",
        f"G00 {xyz(P[0])}",
        f"G5.2 P{num(w[0])} L{seg.degree + 1} F{num(feed_mm_min)}",
    ]
    lines += [f"X{num(P[i, 0])} Y{num(P[i, 1])} P{num(w[i])}" for i in range(1, P.shape[0])]
    lines += ["G5.3", "G00 X0 Y0"]
    return "\n".join(lines) + "\n"


def linuxcnc_knots(n_points: int, order: int) -> np.ndarray:
    """LinuxCNC's knot_vector_creator(n, k) (nurbs_additional_functions.cc), n = points - 1."""
    n, k = n_points - 1, order
    out = []
    for i in range(n + k + 1):
        if i < k:
            out.append(0.0)
        elif i <= n:
            out.append(float(i - k + 1))
        else:
            out.append(float(n - k + 2))
    return np.array(out)
