"""The heavy elastica: a cantilever strip bending under its own weight.

With arc length s from the clamp, theta(s) the slope below the horizontal,
w the weight per area (N/m^2) and B the bending stiffness per width (N m),
moment balance gives  B theta'' = -w (L - s) cos theta,  theta(0) = 0,
theta'(L) = 0.  In s/L the solution depends on the one number
Lambda = w L^3 / B only; its tip sits at
x/L = int cos theta, z/L = -int sin theta.

Peirce's cantilever (ASTM D1388) slides the strip over the edge until the
chord from the edge to the tip is 41.5 degrees below the horizontal and
reports the bending length c = L / 2, which assumes Lambda = 8 there
(Peirce 1930's approximate formula c = L (cos(theta/2) / (8 tan theta))^(1/3)
at theta = 41.5 degrees).  The exact elastica gives the Lambda of that
chord angle (:func:`peirce_load`), so a measured overhang L gives
B = w L^3 / Lambda exactly.
"""
from __future__ import annotations

import functools
import math

import numpy as np
from scipy.integrate import solve_bvp
from scipy.optimize import brentq

PEIRCE_ANGLE = math.radians(41.5)


def tip(load: float) -> tuple[float, float]:
    """(x, z) of the tip over L for Lambda = ``load`` (z < 0: below the clamp)."""
    def rhs(s, y):                       # y = (theta, theta', x, -z)
        return np.vstack([y[1], -load * (1.0 - s) * np.cos(y[0]), np.cos(y[0]),
                          np.sin(y[0])])

    def bc(a, b):
        return np.array([a[0], b[1], a[2], a[3]])
    s = np.linspace(0.0, 1.0, 201)
    guess = np.vstack([np.zeros_like(s), np.zeros_like(s), s, np.zeros_like(s)])
    sol = solve_bvp(rhs, bc, s, guess, tol=1e-10, max_nodes=100000)
    if sol.status != 0:
        raise RuntimeError(f"heavy elastica: {sol.message}")
    end = sol.sol(1.0)
    return float(end[2]), -float(end[3])


def chord_angle(load: float) -> float:
    """Angle below the horizontal of the chord from the clamp to the tip (rad)."""
    x, z = tip(load)
    return math.atan2(-z, x)


@functools.lru_cache(maxsize=None)
def peirce_load(angle: float = PEIRCE_ANGLE) -> float:
    """The Lambda = w L^3 / B at which the chord is at ``angle``."""
    return brentq(lambda lam: chord_angle(lam) - angle, 0.5, 60.0, xtol=1e-13)


def peirce_formula(angle: float) -> float:
    """Peirce's bending length over overhang, (cos(theta/2) / (8 tan theta))^(1/3)."""
    return (math.cos(angle / 2.0) / (8.0 * math.tan(angle))) ** (1.0 / 3.0)
