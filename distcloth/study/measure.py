"""What a stability run measures after each step, independently of the
simulator's own diagnostics (collective: every rank calls these together
and gets the same numbers).

* ``PenetrationOracle``: the worst depth (d - phi) / d of a free vertex inside
  a collider, from fresh collider objects built from the scene (analytic
  signed distances), at the step's end time.
"""
from __future__ import annotations

import numpy as np

from ..collision.colliders import AnalyticCollider, Box, Capsule, Plane, RigidMotion, Sphere


class PenetrationOracle:
    """Signed distances to the scene's analytic colliders (mesh colliders are
    not used by the stability cases)."""

    def __init__(self, cfg):
        shapes = {"plane": Plane, "sphere": Sphere, "capsule": Capsule, "box": Box}
        self.bodies = []
        if not cfg.has("collisions"):
            return
        cloth_d = max(c.thickness for c in cfg.cloth)
        for spec in cfg.colliders:
            if spec.shape not in shapes:
                raise ValueError(f"collider {spec.name}: the stability oracle handles analytic "
                                 f"shapes only, not {spec.shape}")
            motion = None
            if spec.motion is not None:
                motion = RigidMotion(spec.motion.times, spec.motion.translations,
                                     spec.motion.rotations)
            body = AnalyticCollider(shapes[spec.shape](**dict(spec.geometry)), motion, 0.0, 0.0)
            self.bodies.append((body, cloth_d + spec.thickness))

    @property
    def active(self) -> bool:
        return bool(self.bodies)

    def worst(self, sim) -> float:
        """max over free owned vertices and colliders of (d - phi) / d (NaN without colliders)."""
        if not self.bodies:
            return float("nan")
        n = sim.n_owned
        free = np.ones(n, dtype=bool)
        for held in (sim.pinned_local, sim.slide_local):
            free[held[held < n]] = False
        x = sim.state.x[:n][free]
        worst = -np.inf
        for body, d in self.bodies:
            if x.shape[0]:
                phi = body.query(x, sim.state.t)[0]
                # NaN positions give NaN depths: count them as infinitely deep
                depth = np.where(np.isfinite(phi), (d - phi) / d, np.inf)
                worst = max(worst, float(depth.max()))
        return float(sim.comm.max(np.array([worst]))[0])
