"""The curves a panel edge can follow: straight line, circular arc, quadratic
or cubic Bézier, all in the panel's 2D frame (metres).

Every curve offers ``point(s)`` and ``tangent(s)`` for ``s`` in [0, 1]
measured by arc length (s = 0 at the edge's start, 1 at its end; a scalar
gives one point, an array of n values an (n, 2) array) and ``length()``.

Lines and arcs are parametrised by arc length exactly.  A Bézier curve's
length is integrated by composite Gauss–Legendre quadrature (8 nodes per
interval; the interval count is doubled until two estimates agree to 1e-13
relative), and ``s`` is turned into the curve parameter t by a safeguarded
Newton iteration on that integral, started from linear interpolation in the
table of cumulative lengths and kept inside its interval: positions are exact
to ~1e-12 of the edge length.

Arc convention (GarmentCode's ``circle`` curvature, pygarment
``pygarment/garmentcode/edge.py`` CircleEdge.as_radius_flag and
``pygarment/meshgen/boxmeshgen.py`` Edge.init_curve, which hands
``sweep=right`` to an SVG arc): ``right`` true means the arc lies on the right
of the chord walked from start to end (in a y-up frame), i.e. it runs
counter-clockwise about its centre; ``large`` picks the arc of more than
180 degrees.  As in SVG, a radius shorter than half the chord is taken as
half the chord (a half circle).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

# Gauss–Legendre nodes and weights on [0, 1]
_GL_X, _GL_W = np.polynomial.legendre.leggauss(8)
_GL_X = 0.5 * (_GL_X + 1.0)
_GL_W = 0.5 * _GL_W


def frozen_array(values, shape_tail=None) -> np.ndarray:
    """A float64 copy that cannot be written to (the dataclasses here are frozen)."""
    out = np.array(values, dtype=np.float64)
    if shape_tail is not None and out.shape[-len(shape_tail):] != shape_tail:
        raise ValueError(f"expected shape (..., {', '.join(map(str, shape_tail))}), got {out.shape}")
    out.flags.writeable = False
    return out


def _as_fractions(s):
    s = np.asarray(s, dtype=np.float64)
    return s, s.ndim == 0


@dataclass(frozen=True, eq=False)
class Line:
    """Straight edge from ``start`` to ``end``."""
    start: np.ndarray
    end: np.ndarray
    kind: str = field(default="line", init=False)

    def __post_init__(self):
        object.__setattr__(self, "start", frozen_array(self.start, (2,)))
        object.__setattr__(self, "end", frozen_array(self.end, (2,)))

    def length(self) -> float:
        return float(np.hypot(*(self.end - self.start)))

    def point(self, s) -> np.ndarray:
        s, scalar = _as_fractions(s)
        out = self.start + np.multiply.outer(np.atleast_1d(s), self.end - self.start)
        return out[0] if scalar else out

    def tangent(self, s) -> np.ndarray:
        s, scalar = _as_fractions(s)
        d = (self.end - self.start) / self.length()
        out = np.broadcast_to(d, (np.atleast_1d(s).size, 2)).copy()
        return out[0] if scalar else out

    def reversed(self) -> "Line":
        return Line(self.end, self.start)


@dataclass(frozen=True, eq=False)
class CircularArc:
    """Circular arc from ``start`` to ``end`` of the given ``radius``; ``right``:
    the arc lies right of the chord start -> end (counter-clockwise about the
    centre); ``large``: the arc spans more than half the circle."""
    start: np.ndarray
    end: np.ndarray
    radius: float
    large: bool
    right: bool
    kind: str = field(default="arc", init=False)
    center: np.ndarray = field(init=False)
    angle0: float = field(init=False)        # polar angle of start about the centre
    sweep: float = field(init=False)         # signed angle swept (> 0: counter-clockwise)

    def __post_init__(self):
        a, b = frozen_array(self.start, (2,)), frozen_array(self.end, (2,))
        object.__setattr__(self, "start", a)
        object.__setattr__(self, "end", b)
        chord = b - a
        d = float(np.hypot(*chord))
        if not d > 0.0:
            raise ValueError("an arc needs distinct endpoints")
        if not (np.isfinite(self.radius) and self.radius > 0.0):
            raise ValueError(f"arc radius must be a finite number > 0, got {self.radius!r}")
        r = max(float(self.radius), 0.5 * d)          # SVG: too small a radius becomes d/2
        object.__setattr__(self, "radius", r)
        object.__setattr__(self, "large", bool(self.large))
        object.__setattr__(self, "right", bool(self.right))
        left_normal = np.array([-chord[1], chord[0]]) / d
        k = np.sqrt(max(r * r - 0.25 * d * d, 0.0))
        # a right small arc and a left large one have their centre left of the chord
        side = 1.0 if self.right != self.large else -1.0
        c = 0.5 * (a + b) + side * k * left_normal
        object.__setattr__(self, "center", frozen_array(c))
        t0 = float(np.arctan2(*(a - c)[::-1]))
        t1 = float(np.arctan2(*(b - c)[::-1]))
        if self.right:                                # counter-clockwise
            sweep = (t1 - t0) % (2.0 * np.pi)
        else:
            sweep = -((t0 - t1) % (2.0 * np.pi))
        if k == 0.0:                                  # half circle: both arcs have pi
            sweep = np.copysign(np.pi, sweep if sweep != 0.0 else (1.0 if self.right else -1.0))
        object.__setattr__(self, "angle0", t0)
        object.__setattr__(self, "sweep", float(sweep))

    def length(self) -> float:
        return self.radius * abs(self.sweep)

    def point(self, s) -> np.ndarray:
        s, scalar = _as_fractions(s)
        t = self.angle0 + np.atleast_1d(s) * self.sweep
        out = self.center + self.radius * np.stack([np.cos(t), np.sin(t)], axis=-1)
        # the endpoints exactly as given (the centre carries rounding)
        out[np.atleast_1d(s) == 0.0] = self.start
        out[np.atleast_1d(s) == 1.0] = self.end
        return out[0] if scalar else out

    def tangent(self, s) -> np.ndarray:
        s, scalar = _as_fractions(s)
        t = self.angle0 + np.atleast_1d(s) * self.sweep
        out = np.sign(self.sweep) * np.stack([-np.sin(t), np.cos(t)], axis=-1)
        return out[0] if scalar else out


@dataclass(frozen=True, eq=False)
class Bezier:
    """Bézier curve through ``control`` = [start, c1, (c2,) end] (quadratic
    with 3 points, cubic with 4), parametrised by arc length numerically."""
    control: np.ndarray
    kind: str = field(init=False)
    _breaks: np.ndarray = field(init=False, repr=False)     # t at interval ends
    _cumulative: np.ndarray = field(init=False, repr=False)  # length from t=0 to each break

    def __post_init__(self):
        p = frozen_array(self.control, (2,))
        if p.ndim != 2 or p.shape[0] not in (3, 4):
            raise ValueError("a Bézier edge has 1 (quadratic) or 2 (cubic) control points")
        object.__setattr__(self, "control", p)
        object.__setattr__(self, "kind", "quadratic" if p.shape[0] == 3 else "cubic")
        n = 16
        breaks, cum = self._table(n)
        while n < 4096:
            b2, c2 = self._table(2 * n)
            done = abs(c2[-1] - cum[-1]) <= 1e-13 * max(c2[-1], 1e-300)
            breaks, cum, n = b2, c2, 2 * n
            if done:
                break
        object.__setattr__(self, "_breaks", frozen_array(breaks))
        object.__setattr__(self, "_cumulative", frozen_array(cum))

    # -- the polynomial
    def at(self, t) -> np.ndarray:
        """Position at curve parameter t (not arc length)."""
        t = np.asarray(t, dtype=np.float64)[..., None]
        p, u = self.control, 1.0 - np.asarray(t, dtype=np.float64)
        if p.shape[0] == 3:
            return u * u * p[0] + 2.0 * u * t * p[1] + t * t * p[2]
        return u ** 3 * p[0] + 3.0 * u * u * t * p[1] + 3.0 * u * t * t * p[2] + t ** 3 * p[3]

    def derivative(self, t) -> np.ndarray:
        t = np.asarray(t, dtype=np.float64)[..., None]
        p, u = self.control, 1.0 - t
        if p.shape[0] == 3:
            return 2.0 * u * (p[1] - p[0]) + 2.0 * t * (p[2] - p[1])
        return 3.0 * (u * u * (p[1] - p[0]) + 2.0 * u * t * (p[2] - p[1]) + t * t * (p[3] - p[2]))

    def _speed(self, t) -> np.ndarray:
        return np.linalg.norm(self.derivative(t), axis=-1)

    def _table(self, n: int):
        breaks = np.linspace(0.0, 1.0, n + 1)
        a, w = breaks[:-1], np.diff(breaks)
        nodes = a[:, None] + w[:, None] * _GL_X[None, :]
        pieces = (self._speed(nodes) * _GL_W[None, :]).sum(axis=1) * w
        return breaks, np.concatenate([[0.0], np.cumsum(pieces)])

    def _partial(self, t0, t1) -> np.ndarray:
        """Length from t0 to t1 (arrays; each within one table interval)."""
        w = t1 - t0
        nodes = t0[:, None] + w[:, None] * _GL_X[None, :]
        return (self._speed(nodes) * _GL_W[None, :]).sum(axis=1) * w

    def length(self) -> float:
        return float(self._cumulative[-1])

    def parameter(self, s) -> np.ndarray:
        """Curve parameter t at arc-length fraction s (array)."""
        s = np.clip(np.atleast_1d(np.asarray(s, dtype=np.float64)), 0.0, 1.0)
        target = s * self._cumulative[-1]
        k = np.clip(np.searchsorted(self._cumulative, target, side="right") - 1,
                    0, self._breaks.size - 2)
        lo, hi = self._breaks[k], self._breaks[k + 1]
        c0, c1 = self._cumulative[k], self._cumulative[k + 1]
        span = np.where(c1 > c0, c1 - c0, 1.0)
        t = lo + (hi - lo) * np.clip((target - c0) / span, 0.0, 1.0)
        a, b = lo.copy(), hi.copy()                    # bracket of the root
        for _ in range(60):       # Newton converges in a few; bisection needs < 50
            f = c0 + self._partial(lo, t) - target
            a = np.where(f < 0.0, t, a)
            b = np.where(f > 0.0, t, b)
            speed = self._speed(t)
            step = np.where(speed > 0.0, f / np.where(speed > 0.0, speed, 1.0), 0.0)
            t_new = t - step
            # strictly outside: a converged step lands on the bracket's end it just set
            outside = (t_new < a) | (t_new > b) | (speed <= 0.0)
            t_new = np.where(outside, 0.5 * (a + b), t_new)
            if np.all(np.abs(t_new - t) <= 1e-14):     # rounding stalls Newton below this
                t = t_new
                break
            t = t_new
        t[s == 0.0] = 0.0
        t[s == 1.0] = 1.0
        return t

    def point(self, s) -> np.ndarray:
        s_arr, scalar = _as_fractions(s)
        out = self.at(self.parameter(s_arr))
        return out[0] if scalar else out

    def tangent(self, s) -> np.ndarray:
        """Unit tangent; where the derivative vanishes (a control point on an
        endpoint) the direction of the curve's next non-zero derivative."""
        s_arr, scalar = _as_fractions(s)
        t = self.parameter(s_arr)
        d = self.derivative(t)
        n = np.linalg.norm(d, axis=-1)
        small = n <= 1e-12 * max(self.length(), 1e-300)
        if np.any(small):                   # limit direction: step a little along the curve
            eps = 1e-7
            ahead = np.clip(t[small] + eps, 0.0, 1.0)
            behind = np.clip(t[small] - eps, 0.0, 1.0)
            d[small] = self.at(ahead) - self.at(behind)
            n[small] = np.linalg.norm(d[small], axis=-1)
        out = d / n[:, None]
        return out[0] if scalar else out

