"""Sewing forces: stitch springs that close a garment's seams, and the seam
lines of a welded garment.

Stitch springs (the sewing phase; the tutorial's Part 2 §1.2 pre-positioned
panels "sewn" by seam forces): each pair of stitched vertices is joined by a
spring of stiffness k whose rest length goes linearly from the pair's start
gap to zero over the sewing duration (for a piece of layer k, over the k-th
such interval), then stays zero.  The ramp bounds how
fast the seams close (no panel is flung across the body), and once at zero
the spring is the linear zero-length spring f = -k (x_a - x_b), whose
Jacobian k I needs no direction, so coincident pairs are fine.
"""
from __future__ import annotations

import numpy as np

from . import springs as sk
from .base import ForceTerm, local_elements
from .terms import SpringTerm

_COINCIDENT = 1e-12   # m: below this a pair has no direction; its rest length is zero by then


class StitchTerm(ForceTerm):
    """Stitch springs on local vertices (pairs with at least one owned end)."""

    name = "force:sewing"
    has_potential = True

    def __init__(self, pairs, gap, stiffness, duration, weight, owned, start=None):
        self.pairs = np.ascontiguousarray(pairs, dtype=np.int64).reshape(-1, 2)
        self.gap = np.asarray(gap, dtype=np.float64)
        # when each pair's ramp begins (layers are sewn inside out)
        self.start = np.zeros(self.gap.shape) if start is None else np.asarray(start, float)
        self.k = np.full(self.pairs.shape[0], float(stiffness))
        self.duration = float(duration)
        self.weight = np.asarray(weight, dtype=np.float64)
        self.owned = np.asarray(owned, dtype=bool)     # the pair's first end is owned here
        self.rest = self.gap.copy()
        ns = self.pairs.shape[0]
        self.hess = np.zeros((ns, 3, 3))
        self.unit = np.zeros((ns, 3))
        self._zero = np.zeros(ns)
        self.slots = None

    def at_time(self, t: float) -> None:
        """Rest lengths at the end of the attempt ending at time t."""
        self.rest = self.gap * np.clip(1.0 - (t - self.start) / self.duration, 0.0, 1.0)

    def stencils(self):
        return [self.pairs]

    def bind(self, pattern):
        self.slots = pattern.slots_for(self.pairs)

    def _geometry(self, x):
        d = x[self.pairs[:, 0]] - x[self.pairs[:, 1]]
        length = np.sqrt(np.einsum("ij,ij->i", d, d))
        u = d / np.maximum(length, _COINCIDENT)[:, None]
        return d, length, u

    def evaluate(self, x, v, force, want_jac):
        d, length, u = self._geometry(x)
        # f_a = -k (l - r) u; the clamp keeps a coincident pair at zero force
        ext = np.where(length > _COINCIDENT, length - self.rest, 0.0)
        f = -(self.k * ext)[:, None] * u
        np.add.at(force, self.pairs[:, 0], f)
        np.add.at(force, self.pairs[:, 1], -f)
        if want_jac:
            # k [u u^T + max(0, 1 - r/l) (I - u u^T)]: the compressed direction
            # dropped, as for the cloth's own springs (positive semi-definite)
            geo = self.k * np.clip(1.0 - self.rest / np.maximum(length, _COINCIDENT), 0.0, 1.0)
            geo = np.where(length > _COINCIDENT, geo, self.k)
            self.hess[:] = ((self.k - geo)[:, None, None] * np.einsum("ni,nj->nij", u, u)
                            + geo[:, None, None] * np.eye(3)[None])
            self.unit[:] = u

    def stiffness_product(self, w, out):
        sk.spring_stiffness_product(self.pairs, self.hess, w, out)

    def add_to_system(self, data, alpha, beta):
        sk.add_spring_blocks(self.hess, self.unit, self._zero, alpha, 0.0, self.slots, data)

    def energy(self, x):
        _, length, _ = self._geometry(x)
        return float(np.sum(0.5 * self.k * np.square(length - self.rest) * self.weight))

    def largest_gap(self, x) -> float:
        """The largest distance between this rank's stitched pairs (owned first end)."""
        _, length, _ = self._geometry(x)
        return float(np.max(length[self.owned], initial=0.0))


def build_sewing(cfg, model, layout) -> ForceTerm | None:
    """Stitch springs while a garment's stitches are not yet welded."""
    if model.stitch_pairs is None:
        return None
    distinct = model.stitch_pairs[:, 0] != model.stitch_pairs[:, 1]
    pairs, gap = model.stitch_pairs[distinct], model.stitch_gap[distinct]
    local, weight, ids = local_elements(pairs, layout)
    sewing = cfg.garment.sewing
    # the initial-layering rule, in time: a piece of layer k closes its seams
    # over the k-th sewing interval, after the garments under it are closed
    # (an outer panel's edge would otherwise slip into an inner garment's
    # still open seam and be caught there)
    layer = model.per_vertex([float(spec.layer) for spec in cfg.cloth])
    start = layer[pairs[ids, 0]] * sewing.duration
    return StitchTerm(local, gap[ids], sewing.stiffness, sewing.duration, weight,
                      local[:, 0] < layout.n_owned, start)


def build_seams(cfg, model, layout) -> ForceTerm | None:
    """The seam lines of a welded garment: springs along its seam edges."""
    if model.seam_lines is None or model.seam_lines.shape[0] == 0:
        return None
    local, weight, ids = local_elements(model.seam_lines, layout)
    # strain_mask off: a shrunk seam is shorter than its fabric by design and
    # must not count as the membrane's strain
    return SpringTerm("force:seams", local, model.seam_rest_length[ids],
                      model.seam_stiffness[ids], weight, np.zeros(ids.size, dtype=bool))
