"""Contact: the one module that decides how cloth meets bodies and itself.

Read top to bottom, this is what a step does with contact (the kernels it
calls are array functions in ``response.py``, ``friction.py``,
``impulses.py``, ``imagespace.py`` and ``physics/contact_friction.py``):

1. **Colliders** (``Collider``, built once from the scene): analytic shapes,
   mesh colliders answered through BVH closest points (``mesh_query.py``) or
   through image-space maps (``image_collider.py``, Vassilev et al. 2001 §4),
   each with its thickness, friction, motion and, chosen here once for the
   scene, its **friction law**: in the solve for implicit schemes
   (``force:friction``), after the step for explicit ones, and Vassilev et
   al.'s Eq. 15 for image-space colliders whatever the scheme.  Garments
   worn in layers add one more per outer layer: the surface of the layers
   under it, placed anew where each step starts (``layers.py``).
2. **Detection** (stage ``collision:bodies``, before the solve): a vertex
   predicted to come within d = cloth + collider thickness becomes a
   Baraff-Witkin constraint S = I - n n^T with the normal velocity that stops
   it at d (EG07 tutorial Part 1 §2.3 names both constraint and impulse
   responses; constraints for resting contact because the implicit solve
   then sees the contact: no bouncing on a sphere or a plane at 5 ms steps,
   which impulses after an unconstrained solve gave).
3. **Constraints**: the contacts' (S, z), joined to the pins' by the driver.
4. **Friction in the solve**: ``begin_attempt`` hands the contacts whose law
   is in-solve to the friction force term.
5. **Missed contacts**: a free vertex that ends the solve deeper than
   MISSED_FRACTION d inside a body makes the driver solve the attempt again
   with it as a contact.
6. **Response** (stage ``collision:response``, after the solve): after-step
   Coulomb friction or Eq. 15 on the contacts whose law says so, adhesive
   contacts marked for release, the **position fail-safe** against the
   distance fields, then the **triangle pipeline** of Bridson et al. 2002
   (mesh colliders with method bvh, plane colliders as kinematic quads and,
   with self_collision, cloth against cloth) on the motion that includes the
   fail-safe's projection: proximity repulsion, CCD impulses and rigid
   impact zones, on candidates the ranks find over the replicated BVH
   (``parallel/collide.py``).

Every rank computes the same contact for a shared vertex (ghosts included);
the triangle pipeline runs on the all-gathered cloth from the canonical,
sorted candidate set, so results depend neither on the order contacts were
found in nor on which rank found them.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ..parallel.collide import build_collisions
from ..config.schema import ConfigError
from ..physics.contact_barrier import BarrierContactTerm
from ..physics.contact_friction import ContactFrictionTerm
from .colliders import (AnalyticCollider, Box, Capsule, MeshCollider, Plane, RigidMotion,
                        Sphere, load_collider_mesh)
from .image_collider import ImageSpaceCollider
from .imagespace import velocity_response
from .impulses import ReusedCandidates, resolve
from .layers import LayerSurface
from .mesh_query import MeshProximity
from .proximity import mesh_edges
from .sagitta import body_clearance
from .response import Contacts, contact_constraint, detect, friction, normal_impulse, project

MAX_CONTACT_PASSES = 4   # solves per attempt at most while the contact set changes
CONTACT_PASS_RTOL = 1e-3  # relative residual of the solves that only settle the contact set
                          # (the last is solved again to the scene's tolerance)
MISSED_FRACTION = 0.05   # a free vertex ending deeper than this fraction of d is a missed contact
BAND_FRACTION = 0.5      # a vertex that ended the last step within this fraction of d above d
                         # and is predicted to end this one there too is a contact, held at
                         # its free-flight approach (response.detect): contact sets persist,
                         # so the first solve is usually right, and tension that presses cloth
                         # onto a body meets the solve, not the fail-safe
ADHESION_TOLERANCE = 1e-3   # a contact is adhesive when its constraint pulls by more than this
                            # fraction of the vertex's weight impulse m g h
BODY_CLEARANCE_FLOOR = 0.1      # cloth pairs with a closed mesh collider's primitives keep the
                                # thickness less the cloth's sagitta over the body's curvature
                                # (sagitta.py), at least this fraction of it: the CCD's margin
CANDIDATE_SLACK = 0.5    # the CCD passes of a step reuse their candidates while no end position
                         # moved more than this fraction of the thickness (impulses.ReusedCandidates)

# friction laws
IN_SOLVE = "in_solve"        # a damping force of the implicit solve (physics/contact_friction.py)
AFTER_STEP = "after_step"    # Coulomb clamp of the velocities after the step (response.friction)
EQ15 = "eq15"                # Vassilev et al. 2001 Eq. 15: C_fric = 1 - mu keeps the tangential part

ANALYTIC_SHAPES = {"plane": Plane, "sphere": Sphere, "capsule": Capsule, "box": Box}


def friction_law(kind: str, implicit: bool) -> str:
    """The friction law of a collider of ``kind`` under an implicit or explicit scheme."""
    if kind == "image":
        return EQ15
    return IN_SOLVE if implicit else AFTER_STEP


@dataclass
class Collider:
    """A body the cloth collides with, as the step sees it."""
    name: str
    kind: str                   # analytic | mesh | image | layer
    query: Callable             # (x, t, max_distance) -> (phi, normal, velocity) at x
    friction: float             # Coulomb mu
    thickness: float            # m, added to the cloth's
    law: str                    # friction law (friction_law)
    body: AnalyticCollider | MeshCollider | None   # geometry and motion (pictures, checks)
    closed: bool = True         # has an inside: the position fail-safe applies
    drive_end: float = 0.0      # s: the last keyframe or frame (it moves until then)
    mesh: MeshCollider | None = None                  # in the triangle pipeline (bvh meshes)
    image_error_bound: tuple[float, float] | None = None   # image-space maps: Eq. 14 (du, dv), m
    region: str | None = None   # a moving body's part in the contact (animation.reach)


def rigid_motion(spec) -> RigidMotion | None:
    """The collider's keyframed rigid motion, or None."""
    if spec.motion is None:
        return None
    return RigidMotion(spec.motion.times, spec.motion.translations, spec.motion.rotations)


def make_collider(spec, implicit: bool, key: str = "colliders", garment_points=None) -> Collider:
    """The collider a scene's ``colliders:`` entry (at ``key``) describes;
    ``garment_points``: where the cloth starts (a moving body's reach)."""
    motion = rigid_motion(spec)
    drive_end = float(motion.times[-1]) if motion is not None else 0.0
    common = dict(name=spec.name, friction=spec.friction, thickness=spec.thickness)
    if spec.shape != "mesh":
        body = AnalyticCollider(ANALYTIC_SHAPES[spec.shape](**dict(spec.geometry)), motion,
                                spec.friction, spec.thickness)
        return Collider(kind="analytic", query=lambda x, t, maxd: body.query(x, t), body=body,
                        law=friction_law("analytic", implicit), drive_end=drive_end, **common)
    if spec.animation is not None:
        if spec.method == "image" and spec.animation.reach is not None:
            raise ConfigError(f"{key}.animation.reach", spec.animation.reach,
                              "null with method: image (the maps are of the whole body)")
        # the body rig (BVH, skinning, retargeting: 0.3 s of imports) only for animated bodies
        from ..scene.animated_body import load_animated_collider
        mesh = load_animated_collider(spec, key, motion)
        drive_end = max(drive_end, mesh.drive_end)
    else:
        mesh = load_collider_mesh(spec, motion, key)
        drive_end = max(drive_end, float(mesh.frame_times[-1]))
    if spec.method == "image":
        img = ImageSpaceCollider(mesh, resolution=tuple(spec.resolution),
                                 axis="xyz".index(spec.axis))
        return Collider(kind="image", query=img.query, body=mesh,
                        law=friction_law("image", implicit), drive_end=drive_end,
                        image_error_bound=tuple(float(e) for e in img.error_bound), **common)
    region, drawn = None, mesh
    if spec.animation is not None and spec.animation.reach is not None and garment_points is not None:
        # the contact sees only the part in reach; pictures and output the whole body
        # the body rig's imports only for animated bodies (see above)
        from ..scene.animated_body import reachable_part
        mesh, region = reachable_part(mesh, garment_points, spec.animation.reach)
    prox = MeshProximity(mesh)
    return Collider(kind="mesh", query=prox.query, body=drawn, law=friction_law("mesh", implicit),
                    closed=bool(prox.closed), drive_end=drive_end, mesh=mesh, region=region,
                    **common)


def plane_quad(spec, rest_positions) -> MeshCollider:
    """A plane collider as a kinematic two-triangle quad for the triangle
    pipeline, far larger than the cloth (100 times its size plus 10 m), with
    the plane's motion.  Bridson et al. 2002 push bodies through the same
    impulses and impact zones as the cloth: a floor that only the contact
    constraints and the position fail-safe knew about let the fail-safe lift
    a layer of a pile through the layer above it."""
    rest = np.asarray(rest_positions, dtype=np.float64)
    corners, tris = Plane(**dict(spec.geometry)).quad(rest.mean(axis=0),
                                                      100.0 * float(np.ptp(rest, axis=0).max()) + 10.0)
    return MeshCollider(corners[None], tris, motion=rigid_motion(spec),
                        friction=spec.friction, thickness=spec.thickness)


@dataclass
class ContactRevision:
    """What an attempt's solves showed about its contacts (local rows)."""
    released: np.ndarray        # (n_local,) bool: adhesive, not a contact for the rest of the attempt
    missed: np.ndarray          # (k, n_local) bool: contacts that land at d whatever the prediction


@dataclass
class ContactReport:
    """What one attempt's contact response measured (this rank's part); the
    works are in J, over the step, relative to the bodies' motion."""
    contacts: int = 0
    max_penetration: float = -np.inf
    projected_vertices: int = 0
    impulse_hits: float = 0.0
    impact_zone_vertices: float = 0.0
    self_intersections: float = 0.0
    contact_work: float = 0.0        # the contact constraints of the solve
    friction_work: float = 0.0       # friction, in the solve or after it
    failsafe_work: float = 0.0       # the position fail-safe (kinetic + gravitational)
    impulse_work: float = 0.0        # the triangle pipeline (kinetic + gravitational)


@dataclass
class ContactResponse:
    """The response stage's result: the corrected proposal and what it measured."""
    x: np.ndarray
    v: np.ndarray
    # (k, n_local) bool: within (1 + BAND_FRACTION) d of each body at the end of
    # the step (before the fail-safe): the next step keeps these contacts
    touching: np.ndarray | None
    report: ContactReport = field(default_factory=ContactReport)


class ContactModel:
    """Contact of one rank's cloth: every method is collective."""

    def __init__(self, cfg, model, layout, comm, ghosts, mass, held, implicit: bool):
        self.comm, self.ghosts = comm, ghosts
        self.n_owned, self.n_local = layout.n_owned, layout.n_local
        self.mass = mass
        self.self_collision = cfg.has("self_collision")
        collider_specs = cfg.colliders if cfg.has("collisions") else ()
        self.colliders = [make_collider(spec, implicit, f"colliders.{i}", model.start_positions())
                          for i, spec in enumerate(collider_specs)]
        if model.stitch_pairs is not None:     # a garment being sewn (docs/garments.md)
            for c in self.colliders:
                c.friction *= cfg.garment.sewing.friction
        self.drive_end = max([c.drive_end for c in self.colliders] + [0.0])
        thick = model.per_vertex([float(spec.thickness) for spec in cfg.cloth])
        self.cloth_thickness = thick[layout.local_input]
        self.thickness = float(thick.max(initial=0.0))     # the triangle pipeline's contact distance
        self.never_contact = np.zeros(self.n_local, dtype=bool)   # pins keep their constraint
        self.never_contact[held] = True
        self.sticking = None     # a static relaxation's sticking contacts (stick)
        # a drape lowers it below its residual tolerance: a contact's pull is unbalanced force
        self.adhesion_tolerance = ADHESION_TOLERANCE
        self.pass_rtol = CONTACT_PASS_RTOL     # None: every pass to the scene's tolerance
        self.gravity = np.asarray(cfg.gravity if cfg.has("gravity") else (0.0, 0.0, 0.0), float)
        self.gravity_norm = float(np.linalg.norm(self.gravity))
        # friction as a force of the solve: the colliders whose law says so
        self.friction_term = None
        # contact as a barrier energy of the step (physics/contact_barrier.py)
        # replaces detection, constraints, passes and in-solve friction
        self.barrier = None
        if cfg.contact.model == "barrier" and implicit and self.colliders:
            self.barrier = self._barrier_term(cfg.contact, mass)
        elif any(c.law == IN_SOLVE and c.friction > 0.0 for c in self.colliders):
            self.friction_term = ContactFrictionTerm(mass, self.n_owned)
        self.pipeline_meshes = [c.mesh for c in self.colliders if c.mesh is not None]
        self.detector = None
        if self.pipeline_meshes or self.self_collision:
            closed = [c.closed for c in self.colliders if c.mesh is not None]
            self.pipeline_meshes += [plane_quad(spec, model.rest_positions)
                                     for spec in collider_specs if spec.shape == "plane"]
            # the distance each vertex's pipeline pairs keep: the cloth's (and a
            # plane's, an open mesh's) the thickness; a closed mesh's less its
            # sagitta under the cloth's longest edge (sagitta.py)
            ends = model.rest_positions[mesh_edges(model.triangles)]
            edge = float(np.max(np.linalg.norm(ends[:, 1] - ends[:, 0], axis=1), initial=0.0))
            keep = [np.full(model.num_vertices, self.thickness)]
            for j, m in enumerate(self.pipeline_meshes):
                if j < len(closed) and closed[j]:
                    keep.append(body_clearance(m.vertices(0.0), m.triangles, self.thickness,
                                               edge, BODY_CLEARANCE_FLOOR * self.thickness))
                else:
                    keep.append(np.full(m.vertices(0.0).shape[0], self.thickness))
            self.pipeline_keep = np.concatenate(keep)
            self.cloth_edge = edge
            self.cloth_triangles = np.asarray(model.triangles, dtype=np.int64)
            # garments worn in layers: a pair between layers moves the outer
            # one only (impulses.pair_weights); the bodies rank below every layer
            layer = model.per_vertex([float(spec.layer) for spec in cfg.cloth])
            self.pipeline_priority = None
            if np.unique(layer).size > 1:
                n_mesh = sum(m.vertices(0.0).shape[0] for m in self.pipeline_meshes)
                self.pipeline_priority = np.concatenate([layer, np.full(n_mesh, -1.0)])
            ws = cfg.work_stealing
            self.detector = build_collisions(comm, model, layout, self.pipeline_meshes,
                                             self.self_collision, stealing=ws.enabled, a=ws.a,
                                             b=ws.b, chunk=ws.chunk)
            self.input_mass = model.vertex_mass.astype(np.float64)
            self.input_held = np.zeros(model.num_vertices, dtype=bool)   # kinematic for impulses
            self.input_held[model.pinned] = True
            if model.slide_vertices is not None:
                self.input_held[model.slide_vertices] = True
            self.owned_input = layout.owned_input
            # one mu for the pipeline: the BVH mesh colliders' (plane quads leave
            # their friction to the contact constraints)
            self.pipeline_friction = max([c.friction for c in self.colliders if c.kind == "mesh"]
                                         + [0.0])
        # the scene's colliders (output, pictures); those of the solve also
        # have the layers under each outer garment (layers.py)
        self.bodies = list(self.colliders)
        self.layer_surfaces = []
        if self.self_collision and self.pipeline_priority is not None and self.barrier is None:
            self._add_layer_surfaces(model, layout, implicit)
        self.in_solve = np.array([c.law == IN_SOLVE for c in self.colliders] + [False], dtype=bool)

    def _barrier_term(self, spec, mass) -> BarrierContactTerm:
        """The scene's bodies as a barrier of the step, each vertex's contact
        distance d = cloth + collider thickness; width null: half the largest d."""
        offsets = np.array([self.cloth_thickness + c.thickness for c in self.colliders])
        width = spec.barrier_width
        if width is None:
            width = 0.5 * float(np.max(offsets, initial=0.0))
        return BarrierContactTerm([c.query for c in self.colliders], offsets,
                                  [c.friction for c in self.colliders], self.never_contact, mass,
                                  self.n_owned, width, spec.barrier_stiffness, self.gravity_norm,
                                  spec.static_speed,
                                  convex=[c.kind == "analytic" for c in self.colliders])

    def _add_layer_surfaces(self, model, layout, implicit: bool) -> None:
        """A collider per outer layer: the garments under it, with the
        colliders' friction (the pipeline's mu, as between layers there)."""
        layer = self.pipeline_priority[: model.num_vertices].astype(np.int64)
        for k in np.unique(layer)[1:]:
            surface = LayerSurface(int(k), layer, layout.local_input, model.triangles)
            if surface.empty:
                continue
            self.layer_surfaces.append(surface)
            self.colliders.append(Collider(
                name=f"layers under layer {k}", kind="layer", query=surface.query,
                friction=self.pipeline_friction, thickness=0.0,
                law=friction_law("layer", implicit), body=None, closed=False))

    @property
    def has_bodies(self) -> bool:
        return bool(self.colliders)

    @property
    def has_response(self) -> bool:
        return bool(self.colliders) or self.detector is not None

    @property
    def d_max(self) -> float:
        """The largest contact distance d (cloth + collider thickness)."""
        return float(np.max(self.cloth_thickness, initial=0.0)) + max(
            [c.thickness for c in self.colliders] + [0.0])

    def image_error_bounds(self) -> dict[str, tuple[float, float]]:
        return {c.name: c.image_error_bound for c in self.colliders if c.image_error_bound}

    # ------------------------------------------------------------ queries
    def query(self, x, t, margin=np.inf):
        """(phi (k, n), normal (k, n, 3), velocity (k, n, 3), d (k, n)) at x;
        phi = +inf where a mesh collider is farther than ``margin``."""
        k, n = len(self.colliders), x.shape[0]
        phis, normals, vels = np.empty((k, n)), np.zeros((k, n, 3)), np.zeros((k, n, 3))
        offsets = np.empty((k, n))
        for j, c in enumerate(self.colliders):
            offsets[j] = self.cloth_thickness[:n] + c.thickness
            maxd = margin if np.isscalar(margin) else float(np.max(margin[j], initial=0.0))
            phis[j], normals[j], vels[j] = c.query(x, t, maxd)
        return phis, normals, vels, offsets

    def support(self, x, t, n):
        """(touching, normal, mu, gap) of the first n local vertices at
        positions x: a vertex within the contact band of its deepest body
        (gap = phi - d <= BAND_FRACTION d) touches it, with that body's
        outward normal and Coulomb mu.  Local: no exchange."""
        if not self.colliders:
            return np.zeros(n, dtype=bool), np.zeros((n, 3)), np.zeros(n), np.full(n, np.inf)
        phis, normals, _, offsets = self.query(x[:n], t, (1.0 + BAND_FRACTION) * self.d_max)
        gap = phis - offsets
        deepest = np.argmin(gap, axis=0)
        rows = np.arange(n)
        touching = gap[deepest, rows] <= BAND_FRACTION * offsets[deepest, rows]
        touching &= ~self.never_contact[:n]
        mu = np.array([c.friction for c in self.colliders])[deepest]
        return touching, normals[deepest, rows], mu, gap[deepest, rows]

    def push_out(self, x, t):
        """The positions x (every local row) with each vertex inside a closed
        body moved along its normal to phi = d (a static relaxation's
        fail-safe; the same answer for a vertex on every rank that holds it)."""
        free = ~self.never_contact[: x.shape[0]]
        x, _, _ = self._project_out(x.copy(), np.zeros_like(x), t, free)
        return x

    def _project_out(self, x, v, t, free, queried=None):
        """Distance-field colliders in turn: the ``free`` vertices inside
        moved out along n (inward relative normal velocity removed); x, v
        updated in place.  Returns (x, v, moved mask)."""
        reach = (1.0 + BAND_FRACTION) * self.d_max
        phis, normals, vels, offsets = queried if queried is not None else \
            self.query(x, t, reach)
        moved = np.zeros(x.shape[0], dtype=bool)
        for j, c in enumerate(self.colliders):
            if not c.closed:
                continue
            if moved.any():     # an earlier collider's projection moved vertices: query again
                phis[j], normals[j], vels[j] = c.query(x, t, reach)
            xs, vs, inside = project(x[free], v[free], phis[j][free], normals[j][free],
                                     vels[j][free], offsets[j][free])
            x[free], v[free] = xs, vs
            moved[np.nonzero(free)[0][inside]] = True
        return x, v, moved

    def place_layers(self, x, v, t) -> None:
        """The layers under each outer garment where the cloth is at t (local
        rows x, v; one all-gather); nothing without layers.  Collective."""
        if not self.layer_surfaces:
            return
        n = self.n_owned
        rows = self.detector.gather(np.concatenate([x[:n], v[:n]], axis=1))
        for surface in self.layer_surfaces:
            surface.move(rows[:, :3], rows[:, 3:], t)

    # --------------------------------------------------- 2. detection
    def detect(self, state, h: float, revision: ContactRevision | None = None) -> Contacts:
        """The contact set of the attempt on every local vertex (owned and
        ghosts), by the unilateral rule of response.py; ``revision``: what the
        attempt's earlier solves showed (contacts released as adhesive,
        contacts missed)."""
        if self.barrier is not None:     # no contact set: the barrier sees the bodies at t + h
            self.barrier.begin_step(state.t + h)
            return Contacts.none()
        x, v = state.x, state.v
        if revision is None:
            self.place_layers(x, v, state.t)
        forced = revision.missed if revision is not None else None
        exclude = self.never_contact
        if revision is not None:
            exclude = exclude | revision.released
        speed = float(np.sqrt(np.max(np.einsum("ij,ij->i", v, v), initial=0.0)))
        # how far a vertex can be from a body and still touch it this step
        reach = (1.0 + BAND_FRACTION) * self.d_max + h * speed + h * h * self.gravity_norm
        phis, normals, vels, offsets = self.query(x, state.t, np.inf if forced is not None else reach)
        frictions = np.array([c.friction for c in self.colliders])
        # what touched a body at the end of the last step: the solve's contacts,
        # and vertices pressed against a body that the fail-safe put back
        persistent = state.touching
        # free flight continues the last step's acceleration (tension and support
        # included); before any step, gravity's
        accel = self.gravity if state.acceleration is None else state.acceleration
        return detect(phis, normals, vels, v, offsets, frictions, h, accel,
                      BAND_FRACTION * offsets, exclude, persistent, forced)

    # ------------------------------------------------- 3. constraints
    def constraints(self, contacts: Contacts, v):
        """(index, S, z) of the contacts (never on held vertices); a contact
        the drape marked as sticking (``stick``) is held whole: S = 0, its
        velocity brought to the body's (tangentially) and its target
        (normally)."""
        S, z = contact_constraint(contacts, v)
        if self.sticking is not None and contacts.index.size:
            held = self.sticking[contacts.index]
            n, u = contacts.normal[held], contacts.velocity[held]
            S[held] = 0.0
            z[held] = (u - np.einsum("ni,ni->n", u, n)[:, None] * n
                       + contacts.target[held, None] * n - v[contacts.index[held]])
        return contacts.index, S, z

    def stick(self, owned_mask) -> None:
        """A static relaxation's sticking contacts (Baraff and Witkin 1998 §5:
        a stuck contact is a constraint): the owned vertices of ``owned_mask``
        that become contacts are held still on the body instead of creeping
        under the regularised friction force (physics/contact_friction.py);
        None: none (a simulation's rule)."""
        if owned_mask is None:
            self.sticking = None
            return
        self.sticking = np.zeros(self.n_local, dtype=bool)
        self.sticking[: owned_mask.size] = owned_mask

    # ---------------------------------------------- 4. friction in the solve
    def begin_attempt(self, contacts: Contacts, h: float) -> None:
        if self.friction_term is not None:
            use = self.in_solve[contacts.collider] if contacts.collider.size \
                else np.zeros(0, dtype=bool)
            if self.sticking is not None and contacts.index.size:
                use = use & ~self.sticking[contacts.index]    # held whole: no friction force
            self.friction_term.begin_step(contacts, h, use)

    # ----------------------------------- 5. adhesive and missed contacts
    def revise(self, contacts: Contacts, result, t_end: float, h: float,
               revision: ContactRevision | None):
        """After a solve: contacts whose constraint pulled the vertex toward the
        body (a negative normal impulse beyond ``adhesion_tolerance`` of its weight
        impulse) are released, and free vertices that end deeper than
        MISSED_FRACTION d inside a body become contacts that land at d.
        Returns the revision (accumulated over the attempt's solves) if the
        contact set changes on any rank, else None."""
        n, k = self.n_owned, len(self.colliders)
        flags = np.zeros((self.n_local, 1 + k))
        mine = contacts.index < n
        idx = contacts.index[mine]
        if result.reaction is not None and idx.size:
            impulse = np.einsum("ni,ni->n", result.reaction[idx], contacts.normal[mine])
            scale = self.mass[idx] * h * max(self.gravity_norm, 1.0)
            flags[idx[impulse < -self.adhesion_tolerance * scale], 0] = 1.0
        phis, _, _, offsets = self.query(result.x, t_end, self.d_max)
        free = ~self.never_contact[:n]
        free[idx] = False
        flags[:n, 1:] = ((offsets - phis > MISSED_FRACTION * offsets) & free[None]).T
        if revision is not None:
            # only what the revision does not already hold changes the contact
            # set; a missed contact lands at d even if its landing pulls
            flags[:n, 0] *= ~(revision.released[:n] | revision.missed[:, :n].any(axis=0))
            flags[:n, 1:] *= ~revision.missed[:, :n].T
        if self.comm.max(np.array([float(flags.any())]))[0] == 0.0:
            return None
        self.ghosts.update(flags)
        released, missed = flags[:, 0] > 0.5, flags[:, 1:].T > 0.5
        if revision is not None:
            released |= revision.released
            missed |= revision.missed
        # a vertex pushed deep inside after its release lands at d after all
        return ContactRevision(released & ~missed.any(axis=0), missed)

    # ------------------------------------------------------- 6. response
    def respond(self, state, contacts: Contacts | None, result, h: float) -> ContactResponse:
        """After the solve: friction of the after-step laws on the contacts, the
        position fail-safe, the triangle pipeline; and the work each of them
        (and the contact constraints in the solve) did.  ``result``: the
        integrator's StepResult (proposed owned rows, start forces, position
        gain, constraint impulses)."""
        n = self.n_owned
        x_new, v_new = result.x.copy(), result.v.copy()
        gain = result.position_gain
        report = ContactReport()
        if self.barrier is not None:      # the vertices the barrier acts on at the step's end
            report.contacts = self.barrier.touching(result.x)
        elif contacts is not None:
            mine = contacts.index < n
            idx = contacts.index[mine]
            report.contacts = int(idx.size)
            if idx.size:
                normal = contacts.normal[mine]
                u = contacts.velocity[mine]
                v_free = state.v[idx] + h * result.start_forces[idx] / self.mass[idx, None]
                dvn = normal_impulse(v_new[idx], v_free, normal)
                # the constraints' impulses: from the solve, or (explicit schemes)
                # the normal velocity change they made
                impulse = (np.einsum("ni,ni->n", result.reaction[idx], normal)
                           if result.reaction is not None else self.mass[idx] * dvn)
                moved = np.einsum("ni,ni->n", x_new[idx] - state.x[idx] - h * u, normal)
                report.contact_work = float(np.sum(impulse * moved) / h)
                report.friction_work = self._solve_friction_work(state.x, x_new, v_new, h)
                v_after = self._after_step_friction(v_new[idx], contacts, mine, dvn)
                report.friction_work += _kinetic_change(self.mass[idx], v_new[idx] - u, v_after - u)
                x_new[idx] += gain * (v_after - v_new[idx])
                v_new[idx] = v_after
        # the fail-safe before the triangle pipeline: its projection is then
        # part of the motion the CCD checks, so lifting a layer out of a body
        # cannot carry it through the layer above
        t_end = state.t + h
        touching = None
        if self.colliders:
            x0, v0 = x_new.copy(), v_new.copy()
            x_new, v_new, report.max_penetration, put_back, near = \
                self._failsafe(x_new, v_new, t_end)
            report.projected_vertices = int(put_back.sum())
            report.failsafe_work = self._work_of_change(x0, v0, x_new, v_new)
            flags = np.zeros((self.n_local, len(self.colliders)))
            flags[:n] = (near & self._held(contacts, put_back)).T
            self.ghosts.update(flags)
            touching = flags.T > 0.5
        if self.detector is not None:
            x0, v0 = x_new, v_new
            x_new, v_new = self._triangle_contact(state, x_new, v_new, h, gain, report)
            report.impulse_work = self._work_of_change(x0, v0, x_new, v_new)
            if self.self_collision:
                report.self_intersections = float(self._count_crossings(x_new, t_end))
        return ContactResponse(x_new, v_new, touching, report)

    def _solve_friction_work(self, x0, x1, v1, h) -> float:
        """Work of the friction force of the solve over the step, relative to the body."""
        term = self.friction_term
        if term is None or term.index.size == 0 or term.c is None:
            return 0.0
        f = term.force_at(v1[term.index])
        return float(np.sum(f * (x1[term.index] - x0[term.index] - h * term.u)))

    def _work_of_change(self, x0, v0, x1, v1) -> float:
        """Kinetic plus gravitational energy a post-solve correction added to this
        rank's rows (elastic energy it changed is not counted)."""
        m = self.mass[: self.n_owned]
        changed = np.any((x1 != x0) | (v1 != v0), axis=1)
        if not changed.any():
            return 0.0
        m = m[changed]
        return (_kinetic_change(m, v0[changed], v1[changed])
                - float(np.sum(m * ((x1[changed] - x0[changed]) @ self.gravity))))

    def _after_step_friction(self, v, contacts: Contacts, mine, dvn):
        """The velocities of this rank's contacts after the after-step laws."""
        laws = np.array([c.law for c in self.colliders])[contacts.collider[mine]]
        mu = contacts.friction[mine]
        body_v = contacts.velocity[mine]
        normal = contacts.normal[mine]
        out = v.copy()
        coulomb = laws == AFTER_STEP
        if np.any(mu[coulomb] > 0):
            out[coulomb] = friction(v[coulomb], body_v[coulomb], normal[coulomb], mu[coulomb],
                                    dvn[coulomb])
        eq15 = laws == EQ15
        if eq15.any():      # Eq. 15: C_fric keeps 1 - mu of the tangential velocity
            out[eq15] = velocity_response(v[eq15], normal[eq15], body_v[eq15],
                                          np.maximum(0.0, 1.0 - mu[eq15]), 0.0)
        return out

    def _held(self, contacts: Contacts | None, put_back) -> np.ndarray:
        """(k, n_owned) bool: the owned vertices this step's contacts held
        (per collider) or the fail-safe put back (any collider).  Only these
        are kept as contacts by the next step: a vertex that merely ended
        in the band, not pressed (the cloth leaving a body tangentially stays
        within 0.5 d of it for a few cells), would be held still and then
        released as adhesive in every step, the contact passes' chatter
        (docs/collisions.md, "Which contacts a step keeps")."""
        n = self.n_owned
        held = np.zeros((len(self.colliders), n), dtype=bool)
        if contacts is not None and contacts.index.size:
            mine = contacts.index < n
            held[contacts.collider[mine], contacts.index[mine]] = True
        held |= put_back[None]
        return held

    def _failsafe(self, x_new, v_new, t_end):
        """Distance-field colliders at the end of the step: vertices inside
        moved out along n (inward relative normal velocity removed).  The
        penetration it reports is what the solve (and friction) left.
        Open meshes are left to the triangle pipeline (a distance cannot say
        on which side of a zero-thickness panel a vertex belongs)."""
        n = self.n_owned
        free = ~self.never_contact[:n]
        reach = (1.0 + BAND_FRACTION) * self.d_max
        phis, normals, vels, offsets = self.query(x_new, t_end, reach)
        pen = float(np.max((offsets - phis)[:, free], initial=-np.inf))
        touching = (phis < (1.0 + BAND_FRACTION) * offsets) & free[None]
        x_new, v_new, moved = self._project_out(x_new, v_new, t_end, free,
                                                (phis, normals, vels, offsets))
        return x_new, v_new, pen, moved, touching

    def _triangle_contact(self, state, x_new, v_new, h, gain, report):
        """Bridson et al. 2002 on the all-gathered cloth plus the mesh
        colliders' vertices (infinite mass); every rank runs it on the same
        canonical candidates and keeps its own rows."""
        det = self.detector
        n = self.n_owned
        t0, t1 = state.t, state.t + h
        rows = det.gather(np.concatenate([state.x[:n], x_new], axis=1))
        X0 = np.concatenate([rows[:, :3]] + [m.vertices(t0) for m in self.pipeline_meshes])
        X1 = np.concatenate([rows[:, 3:]] + [m.vertices(t1) for m in self.pipeline_meshes])
        U = (X1 - X0) / h
        inv_mass = np.zeros(X0.shape[0])
        free = ~self.input_held
        inv_mass[:det.geometry.n_cloth][free] = 1.0 / self.input_mass[free]
        g = det.geometry
        found = ReusedCandidates(det.candidates, self.thickness, CANDIDATE_SLACK * self.thickness)
        keep = self.pipeline_keep
        if self.layer_surfaces:
            # a garment's vertices under one worn over it keep, as a body's
            # do, the thickness less the outer one's sagitta over their
            # curvature where the step starts: the solve holds the outer
            # vertices at d from the layer's surface (layers.py), and its
            # folds and gathers rise between them (sagitta.py)
            keep = keep.copy()
            keep[:g.n_cloth] = body_clearance(X0[:g.n_cloth], self.cloth_triangles,
                                              self.thickness, self.cloth_edge,
                                              BODY_CLEARANCE_FLOOR * self.thickness)
        U2, stats = resolve(X0, U, h, inv_mass, g.tri, g.edges, self.thickness,
                            self.pipeline_friction, found, hits=det.shared_hits, same=det.same,
                            keep=keep, priority=self.pipeline_priority)
        mine = self.owned_input
        dU = U2[mine] - U[mine]
        report.impulse_hits = float(sum(stats["ccd_hits"]))
        report.impact_zone_vertices = float(stats.get("zone_vertices", 0))
        return x_new + h * dU, v_new + dU * (h / gain)

    def _count_crossings(self, x_new, t1) -> int:
        """Cloth triangle pairs crossing at the end of the step (after the
        fail-safe: what the step hands on)."""
        det = self.detector
        X = np.concatenate([det.gather(x_new[:self.n_owned])]
                           + [m.vertices(t1) for m in self.pipeline_meshes])
        return det.count_intersections(X)

    # ------------------------------------------------------ diagnostics
    def diagnostics(self, report: ContactReport | None) -> dict:
        """Global counts and maxima of the committed step's response."""
        report = report or ContactReport()
        out = {}
        if self.colliders:
            sums = self.comm.sum(np.array([float(report.contacts),
                                           float(report.projected_vertices),
                                           report.contact_work, report.friction_work,
                                           report.failsafe_work]))
            pen = self.comm.max(np.array([float(report.max_penetration)]))[0]
            out.update(contacts=sums[0], max_penetration=pen, projected_vertices=sums[1],
                       contact_work=sums[2], friction_work=sums[3], failsafe_work=sums[4])
        if self.detector is not None:     # replicated values: the same on every rank
            out["impulse_hits"] = report.impulse_hits
            out["impact_zone_vertices"] = report.impact_zone_vertices
            out["impulse_work"] = float(self.comm.sum(np.array([report.impulse_work]))[0])
            if self.self_collision:
                out["self_intersections"] = report.self_intersections
            out.update(self._traversal_diagnostics())
        return out

    def traversal_summary(self) -> str | None:
        """One line on the run's BVH traversals (load balance, stealing), for
        the log; None without a detector."""
        if self.detector is None:
            return None
        c = self.detector.counters
        busy = np.array([c["busy_time"]])
        bmax, bsum = self.comm.max(busy)[0], self.comm.sum(busy)[0]
        counts = self.comm.sum(np.array([c["tasks_created"], c["tasks_stolen"],
                                         c["steals_refused"], c["tests"]], dtype=np.float64))
        wall = self.comm.max(np.array([c["traverse_time"]]))[0]
        mean = bsum / self.comm.size
        ratio = bmax / mean if mean > 0 else 1.0
        mode = "stealing" if self.detector.stealing else "static"
        return (f"BVH traversal ({mode}): {c['refits']} phases, {wall:.2f} s wall, "
                f"busy max/mean {ratio:.2f}, {int(counts[3])} tests, {int(counts[0])} tasks "
                f"created, {int(counts[1])} stolen, {int(counts[2])} refused")

    def _traversal_diagnostics(self) -> dict:
        """The step's BVH traversal over the ranks: busy is CPU time inside
        traversal chunks, not polling; the balance figure is
        traverse_busy_max / traverse_busy_mean."""
        st = self.detector.take_step_stats()
        mx = self.comm.max(np.array([st["busy"], st["wall"], st["latency_max"]]))
        sm = self.comm.sum(np.array([st["busy"], st["idle"], st["tests"], st["tasks_created"],
                                     st["tasks_stolen"], st["steals_refused"], st["msgs_sent"]],
                                    dtype=np.float64))
        p = self.comm.size
        return dict(traverse_wall=mx[1], traverse_busy_max=mx[0], traverse_busy_mean=sm[0] / p,
                    traverse_idle_mean=sm[1] / p, traverse_tests=sm[2], tasks_created=sm[3],
                    tasks_stolen=sm[4], steals_refused=sm[5], steal_messages=sm[6],
                    steal_latency_max=mx[2])


def _kinetic_change(m, v0, v1) -> float:
    """Sum of 1/2 m (|v1|^2 - |v0|^2)."""
    return 0.5 * float(np.sum(m * (np.einsum("ij,ij->i", v1, v1) - np.einsum("ij,ij->i", v0, v0))))
