"""The contract every force term keeps, and the element selection they share.

A term sees local arrays (owned vertices first, then ghosts) and never a
communicator:

* ``stencils()``: element vertex lists whose blocks it writes, fixed for the
  run, from which the matrix sparsity is built once;
* ``bind(pattern)``: remember where its blocks go in the value array;
* ``evaluate(x, v, force, want_jac)``: add its forces to ``force`` and keep
  what the Jacobian needs;
* ``evaluate_between(x0, x1, v, force, want_jac)``: the force of a step from
  x0 to x1 for the energy-momentum midpoint (integrate/implicit.py): a
  discrete gradient, force . (x1 - x0) = -(U(x1) - U(x0)) exactly (Gonzalez
  1996), with the Jacobian kept at the midpoint.  The default evaluates at
  the midpoint, which is exact for energies quadratic in x (gravity,
  isometric bending) and second order for the rest (dihedral bending);
  dissipative terms get the midpoint velocity;
* ``stiffness_product(w, out)``: out += (df/dx) w at the last evaluation;
* ``add_to_system(data, alpha, beta)``: add its part of
  A = M - beta df/dv - alpha df/dx to the block values;
* ``energy(x)``: its potential energy only (0 for dissipative terms),
  weighted so that the ranks' sums add up to the global value once;
* ``dissipation(x, v)``: a dissipative term's potential R with force
  -dR/dv (Rayleigh's, 0 for the rest), weighted alike: the barrier
  contact's Newton line search (integrate/implicit.py) adds it to the step's
  incremental potential;
* ``max_strain(x)``: its largest engineering strain (stretch - 1) at x, 0 for
  terms that do not stretch the membrane.
"""
from __future__ import annotations

import numpy as np


class ForceTerm:
    name = "force"
    has_jacobian = True

    def stencils(self):
        return []

    def bind(self, pattern):
        pass

    def evaluate(self, x, v, force, want_jac):
        pass

    def evaluate_between(self, x0, x1, v, force, want_jac):
        return self.evaluate(0.5 * (x0 + x1), v, force, want_jac)

    def stage(self, x, v, force, want_jac, start=None):
        """The force stage's call: ``evaluate`` at x, or with ``start`` the
        step's force from start to x (``evaluate_between``)."""
        if start is None:
            return self.evaluate(x, v, force, want_jac)
        return self.evaluate_between(start, x, v, force, want_jac)

    def stiffness_product(self, w, out):
        pass

    def add_to_system(self, data, alpha, beta):
        pass

    def energy(self, x):
        return 0.0

    def dissipation(self, x, v):
        return 0.0

    # a force of the velocities alone, -d(dissipation)/dv, whose positions
    # only orient it (StepContext.forces may lag them)
    dissipative = False

    def max_strain(self, x):
        return 0.0


def local_elements(elements: np.ndarray, layout):
    """Elements with at least one owned vertex, in local numbering, and the
    fraction of their vertices this rank owns (their energy weight)."""
    el = layout.input_to_local()[elements]
    owned = (el >= 0) & (el < layout.n_owned)
    keep = owned.any(axis=1)
    if np.any(el[keep] < 0):      # the ghost layer covers every matrix-graph neighbour
        raise RuntimeError("an element with an owned vertex reaches beyond the ghost layer")
    return el[keep], owned[keep].sum(axis=1) / elements.shape[1], np.nonzero(keep)[0]


class TermSum(ForceTerm):
    """Several terms acting as one stage (e.g. mass-spring bending: flexion
    line elements on grids and flexion springs on the other pieces)."""

    def __init__(self, name, parts):
        self.name = name
        self.parts = list(parts)

    def stencils(self):
        return [st for part in self.parts for st in part.stencils()]

    def bind(self, pattern):
        for part in self.parts:
            part.bind(pattern)

    def evaluate(self, x, v, force, want_jac):
        for part in self.parts:
            part.evaluate(x, v, force, want_jac)

    def stiffness_product(self, w, out):
        for part in self.parts:
            part.stiffness_product(w, out)

    def add_to_system(self, data, alpha, beta):
        for part in self.parts:
            part.add_to_system(data, alpha, beta)

    def energy(self, x):
        return sum(part.energy(x) for part in self.parts)

    def dissipation(self, x, v):
        return sum(part.dissipation(x, v) for part in self.parts)

    def max_strain(self, x):
        return max((part.max_strain(x) for part in self.parts), default=0.0)
