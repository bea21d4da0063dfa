"""Pin groups that move (grips), loads and initial velocities of a scene
(docs/loads_and_grips.md): built once from the configuration, the same on
every rank, in input vertex order.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..collision.colliders import RigidMotion
from ..collision.proximity import open_edges
from ..config.schema import ConfigError, PinMotionSpec


class PinPath:
    """Where a grip's vertices are at time t: their start position X moved by
    a constant velocity between start and stop, or by keyframed translations
    T(t) and rotations R(t) about a centre c: y = c + R(t) (X - c) + T(t),
    linear (slerp) between keys and held after the last one."""

    def __init__(self, spec: PinMotionSpec, center: np.ndarray):
        self.spec = spec
        self.center = np.asarray(center, dtype=np.float64)
        self.keys = None
        if spec.velocity is None:
            self.keys = RigidMotion(spec.times, spec.translations, spec.rotations)

    @property
    def end(self) -> float:
        """The time after which the grip is at rest (inf: it never stops)."""
        s = self.spec
        if self.keys is None:
            return math.inf if s.stop is None else float(s.stop)
        return float(s.times[-1])

    def positions(self, X: np.ndarray, t: float, vertices=None) -> np.ndarray:
        """(k, 3) where the vertices starting at X are at t (``vertices``, their
        global indices, matter only to paths that are not rigid: skin_follow.py)."""
        s = self.spec
        if self.keys is None:
            stop = math.inf if s.stop is None else s.stop
            moved = min(max(t, s.start), stop) - s.start
            return X + moved * np.asarray(s.velocity, dtype=np.float64)
        R, p = self.keys.transform(t)
        return self.center + (X - self.center) @ R.T + p

    def velocities(self, X: np.ndarray, t: float, vertices=None) -> np.ndarray:
        """The velocity at t of the interval that starts at t (a key or the
        start/stop time belongs to the motion that follows it)."""
        s = self.spec
        if self.keys is None:
            stop = math.inf if s.stop is None else s.stop
            on = s.start <= t < stop
            return np.tile(np.asarray(s.velocity, dtype=np.float64) * on, (X.shape[0], 1))
        v_p, omega = self.keys.velocity(t)
        R, p = self.keys.transform(t)
        arm = (X - self.center) @ R.T
        return v_p + np.cross(omega, arm)


@dataclass
class Grip:
    """One entry of a piece's pins: its vertices (global, input order), the
    unit axis of a sliding pin (None: held in every direction) and its path
    (None: at rest)."""
    name: str
    vertices: np.ndarray
    axis: np.ndarray | None
    path: PinPath | None


@dataclass
class Loads:
    """External forces: (k,) vertices, (k, 3) full forces (N), (k,) ramp times."""
    vertices: np.ndarray
    forces: np.ndarray
    ramps: np.ndarray

    @staticmethod
    def none() -> "Loads":
        return Loads(np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0))

    @property
    def end(self) -> float:
        """The end of the last ramp (the loads do work on the cloth until then)."""
        return float(self.ramps.max(initial=0.0))

    def total(self) -> float:
        """Sum of the loads' magnitudes at full value, N."""
        return float(np.linalg.norm(self.forces, axis=1).sum())


def piece_grips(spec, pin_sets, positions, offset: int, key: str) -> list[Grip]:
    """A Grip per entry of ``spec.pins`` (``pin_sets``: each entry's piece-local
    vertices), its centre of rotation the group's start centroid unless given."""
    grips = []
    for k, (pin, local) in enumerate(zip(spec.pins, pin_sets)):
        path = None
        if pin.motion is not None:
            center = (pin.motion.center if pin.motion.center is not None
                      else positions[local].mean(axis=0))
            path = PinPath(pin.motion, center)
        axis = None if pin.axis is None else np.asarray(pin.axis, float) / np.linalg.norm(pin.axis)
        grips.append(Grip(f"{spec.name}.pins.{k}", local + offset, axis, path))
    return grips


def piece_loads(spec, load_sets, positions, triangles, offset: int, key: str) -> Loads:
    """The piece's loads lumped to vertices: a point load split equally (or one
    force per index), a line load on the boundary edges whose two ends are
    selected, half of each edge's f * length to each end."""
    parts = [Loads.none()]
    boundary = None
    for k, (load, local) in enumerate(zip(spec.loads, load_sets)):
        n = local.shape[0]
        if load.force is not None:
            forces = np.tile(np.asarray(load.force, float) / n, (n, 1))
            vertices = local
        elif load.forces is not None:
            forces, vertices = np.asarray(load.forces, float).reshape(-1, 3), local
        else:
            if boundary is None:
                boundary = open_edges(triangles)
            chosen = np.zeros(positions.shape[0], dtype=bool)
            chosen[local] = True
            edges = boundary[chosen[boundary].all(axis=1)]
            if edges.shape[0] == 0:
                raise ConfigError(f"{key}.loads.{k}", "line_force",
                                  "a selection holding both ends of at least one boundary edge "
                                  "of the mesh (a line load acts along the boundary)")
            length = np.linalg.norm(positions[edges[:, 1]] - positions[edges[:, 0]], axis=1)
            half = 0.5 * length[:, None] * np.asarray(load.line_force, float)[None]
            vertices = edges.reshape(-1)
            forces = np.repeat(half, 2, axis=0)
        parts.append(Loads(vertices + offset, forces, np.full(vertices.shape[0], load.ramp)))
    return Loads(np.concatenate([p.vertices for p in parts]).astype(np.int64),
                 np.concatenate([p.forces for p in parts]),
                 np.concatenate([p.ramps for p in parts]))


def group_of_vertices(grips: list[Grip], n: int) -> np.ndarray:
    """(n,) each vertex's grip (index into ``grips``), -1 for free vertices; a
    vertex in two entries belongs to the first."""
    group = np.full(n, -1, dtype=np.int64)
    for g in reversed(range(len(grips))):
        group[grips[g].vertices] = g
    return group


def start_velocities(cfg, model) -> np.ndarray | None:
    """(n, 3) each piece's initial velocity plus its angular velocity about the
    piece's centre of mass, with the held directions of pinned vertices at
    their pin's velocity (zero for pins at rest; sliding pins keep the
    velocity across their axis); None when every vertex starts at rest."""
    moving_grips = any(g.path is not None for g in model.grips)
    spin = any(any(spec.initial_velocity) or any(spec.initial_angular_velocity)
               for spec in cfg.cloth)
    if not (spin or moving_grips):
        return model.initial_velocities
    x = model.start_positions()
    v = (np.zeros_like(x) if model.initial_velocities is None
         else np.array(model.initial_velocities, dtype=np.float64))
    for spec, info in zip(cfg.cloth, model.pieces):
        rows = slice(info.vertex_start, info.vertex_stop)
        m = model.vertex_mass[rows]
        centre = (m[:, None] * x[rows]).sum(axis=0) / m.sum()
        v[rows] += np.asarray(spec.initial_velocity, float) + np.cross(
            np.asarray(spec.initial_angular_velocity, float), x[rows] - centre)
    v[model.pinned] = 0.0
    if model.slide_vertices is not None and model.slide_vertices.size:
        a = model.slide_axes
        s = model.slide_vertices
        v[s] -= np.einsum("ni,ni->n", v[s], a)[:, None] * a
    for g, grip in enumerate(model.grips):
        if grip.path is None:
            continue
        rows = grip.vertices[model.pin_group[grip.vertices] == g]
        pv = grip.path.velocities(x[rows], 0.0, rows)
        if grip.axis is not None and not np.isin(rows, model.pinned).all():
            slide = ~np.isin(rows, model.pinned)
            pv[slide] = np.einsum("ni,i->n", pv[slide], grip.axis)[:, None] * grip.axis
        v[rows] += pv
    return v
