"""A test helper: one LP window over the whole first piece of a toolpath, for tests of a window's own parts."""

from __future__ import annotations

from typing import Any

import numpy as np

from geometry import Toolpath
from solvers import lp

#: Knot intervals of the window.
N_INT = 64


def whole_piece_window(tp: Toolpath, lim: lp.LimitSet, Q: float) -> lp.WindowLP:
    """A WindowLP over tp's first piece on N_INT uniform knot intervals (rest at both ends), its geometry breaks
    the toolpath's knots inside the piece, and its largest q set to Q (mm^2/s^2)."""
    piece = tp.pieces[0]

    def geometry(s: np.ndarray) -> Any:
        return tp.evaluate(np.asarray(s, dtype=np.float64) + piece.s_start, piece)

    d = piece.length / N_INT
    breaks = tp.knot_s[(tp.knot_s > 0.0) & (tp.knot_s < piece.length)]
    w = lp.WindowLP(lp.WindowSpec(0, 0, N_INT, d, N_INT, None, True), lim, geometry, "highs", breaks)
    w.Q = Q
    return w
