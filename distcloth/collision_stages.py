"""The collision stages of a step: what a scene's colliders and the
self_collision effect add to the pipeline (nothing, if it names neither).

Three sources of contact, each a stage only when the scene asks for it:

* **Colliders as distance fields** (analytic shapes; mesh colliders through
  BVH closest points, distcloth/collision/mesh_query.py; or through
  image-space maps, distcloth/collision/image_collider.py, seed 002 §4).
  Stage ``collision:bodies`` before the solve: a vertex predicted to come
  within d = cloth + collider thickness becomes a Baraff-Witkin constraint
  S = I - n n^T with the normal velocity that stops it at d (seed 000 Part 1
  §2.3 names both constraint and impulse responses; we chose constraints for
  resting contact because the implicit solve then sees the contact: no
  bouncing on a sphere or a plane at 5 ms steps, which impulses after an
  unconstrained solve gave).  A vertex the prediction missed triggers a
  re-solve with it as a contact.
* **In the solve** (implicit schemes, stage ``force:friction``): Coulomb
  friction as a regularised damping force (physics/contact_friction.py).
* **After the solve** (stage ``collision:response``): for explicit schemes,
  Coulomb friction on the constrained vertices (Bridson et al. 2002:
  tangential change at most μ times the normal one) or, for image-space colliders, seed 002's Eq. 15
  velocity response; a position fail-safe against the distance fields (a
  vertex still inside a closed body is moved out); then the Bridson pipeline
  for *triangle* contact (mesh colliders with method bvh, plane colliders as
  kinematic quads and, with self_collision, cloth against cloth), on the
  motion that includes the fail-safe's projection:
  proximity repulsion, CCD impulses and rigid impact zones on one vertex
  space where collider vertices have infinite mass
  (distcloth/collision/impulses.py), on candidates the ranks find over the
  replicated BVH (distcloth/parallel/collide.py).

Every rank computes the same contact for a shared vertex (ghosts included),
the Bridson pipeline runs on the all-gathered cloth from the canonical,
sorted candidate set, so results depend neither on the order contacts were
found in nor on which rank found them.
"""
from __future__ import annotations

import numpy as np

MAX_CONTACT_PASSES = 3   # solves per attempt at most when contacts were missed
MISSED_FRACTION = 0.05   # a free vertex ending deeper than this fraction of d is a missed contact
CANDIDATE_SLACK = 0.5    # the CCD passes of a step reuse their candidates while no end position
                         # moved more than this fraction of the thickness (impulses.ReusedCandidates)


class CollisionStages:
    def __init__(self, sim, cfg, model, local):
        self.sim = sim
        self.image_error_bounds = {}   # image-space collider name -> Eq. 14 (du, dv) in m
        self.colliders = []       # distance-field colliders: (query(x, t, maxd), friction, d_c, kind)
        self.mesh_colliders = []  # MeshCollider objects in the Bridson pipeline (method bvh)
        self.contacts = None
        self.released = np.zeros(sim.n_local, dtype=bool)
        self.pending_released = None
        self.diag = {}
        self.detector = None
        self.drive_end = 0.0      # s: the last collider keyframe / frame (work done until then)
        self.friction_in_solve = False   # set by the simulation (implicit schemes)
        self.self_collision = cfg.has("self_collision")
        n_local = sim.n_local
        thick = np.zeros(model.num_vertices)
        for piece, spec in zip(model.pieces, cfg.cloth):
            thick[piece.vertex_start:piece.vertex_stop] = spec.thickness
        self.cloth_thickness = thick[local]
        self.thickness = float(thick.max(initial=0.0))     # the Bridson pipeline's contact distance
        self.never_contact = np.zeros(n_local, dtype=bool)  # pins keep their constraint
        self.never_contact[sim.pinned_local] = True
        self.never_contact[sim.slide_local] = True
        self.gravity_norm = float(np.linalg.norm(cfg.gravity)) if cfg.has("gravity") else 0.0
        if cfg.has("collisions"):
            for spec in cfg.colliders:
                self._add_collider(spec)
        if self.mesh_colliders or self.self_collision:
            from .parallel.collide import build_collisions
            if cfg.has("collisions"):
                self.mesh_colliders += [_plane_quad(spec, model.rest_positions)
                                        for spec in cfg.colliders if spec.shape == "plane"]
            ws = cfg.work_stealing
            self.detector = build_collisions(sim.comm, model, sim.layout, self.mesh_colliders,
                                             self.self_collision, stealing=ws.enabled, a=ws.a,
                                             b=ws.b, chunk=ws.chunk)
            self._mass = model.vertex_mass.astype(np.float64)
            self._pinned = np.zeros(model.num_vertices, dtype=bool)
            self._pinned[model.pinned] = True
            if model.slide_vertices is not None:
                self._pinned[model.slide_vertices] = True   # held: kinematic for impulses
            self._owned = sim.layout.owned_input

    @property
    def d_max(self) -> float:
        """The largest contact distance d (cloth + collider thickness)."""
        return float(np.max(self.cloth_thickness, initial=0.0)) + max(
            [c[2] for c in self.colliders] + [0.0])

    @property
    def solve_friction(self) -> bool:
        """Some distance-field collider (not image-space: seed 002 Eq. 15 acts
        after the step) has friction, so an implicit solve can take it in."""
        return any(c[1] > 0.0 and c[3] != "image" for c in self.colliders)

    def solved_friction(self, contacts) -> np.ndarray | None:
        """Mask of the contacts whose friction is a force of the solve."""
        if contacts is None:
            return None
        kinds = np.array([c[3] != "image" for c in self.colliders] + [False], dtype=bool)
        return kinds[contacts.collider] if contacts.collider.size else np.zeros(0, dtype=bool)

    @property
    def has_bodies(self) -> bool:
        return bool(self.colliders)

    @property
    def has_response(self) -> bool:
        return bool(self.colliders) or self.detector is not None

    def _add_collider(self, spec) -> None:
        from .collision.colliders import (AnalyticCollider, Box, Capsule, Plane, Sphere,
                                          load_mesh_collider)
        motion = _motion(spec)
        if motion is not None:
            self.drive_end = max(self.drive_end, float(motion.times[-1]))
        if spec.shape != "mesh":
            shapes = {"plane": Plane, "sphere": Sphere, "capsule": Capsule, "box": Box}
            body = AnalyticCollider(shapes[spec.shape](**dict(spec.geometry)), motion,
                                    spec.friction, spec.thickness)
            self.colliders.append((lambda x, t, maxd, b=body: b.query(x, t), spec.friction,
                                   spec.thickness, "analytic"))
            return
        mesh = load_mesh_collider(list(spec.files), frame_rate=spec.frame_rate, motion=motion,
                                  friction=spec.friction, thickness=spec.thickness)
        if spec.scale != 1.0:
            mesh.frames *= spec.scale
        self.drive_end = max(self.drive_end, float(mesh.frame_times[-1]))
        if spec.method == "image":
            from .collision.image_collider import ImageSpaceCollider
            img = ImageSpaceCollider(mesh, resolution=tuple(spec.resolution),
                                     axis="xyz".index(spec.axis))
            self.colliders.append((img.query, spec.friction, spec.thickness, "image"))
            # seed 002 Eq. 14: the x-y error of the maps, reported with the run
            self.image_error_bounds[spec.name] = [float(e) for e in img.error_bound]
            return
        from .collision.mesh_query import MeshProximity
        prox = MeshProximity(mesh)
        self.colliders.append((prox.query, spec.friction, spec.thickness, "mesh"))
        self.mesh_colliders.append(mesh)

    # ------------------------------------------------------------ queries
    def query(self, x, t, margin=np.inf):
        """(phi (k, n), normal (k, n, 3), velocity (k, n, 3), d (k, n)) at x;
        phi = +inf where a mesh collider is farther than ``margin``."""
        k, n = len(self.colliders), x.shape[0]
        phis, normals, vels = np.empty((k, n)), np.zeros((k, n, 3)), np.zeros((k, n, 3))
        offsets = np.empty((k, n))
        for j, (q, _, dc, _) in enumerate(self.colliders):
            offsets[j] = self.cloth_thickness[:n] + dc
            maxd = margin if np.isscalar(margin) else float(np.max(margin[j], initial=0.0))
            phis[j], normals[j], vels[j] = q(x, t, maxd)
        return phis, normals, vels, offsets

    # ------------------------------------------------------------- stages
    def bodies(self, t, h, missed=None):
        """The contact set of the attempt on every local vertex (owned and
        ghosts). ``missed`` (k, n_local) bool: contacts an earlier pass of the
        attempt missed (they join whatever their prediction says)."""
        from .collision.response import detect
        sim = self.sim
        speed = float(np.sqrt(np.max(np.einsum("ij,ij->i", sim.v, sim.v), initial=0.0)))
        reach = self.d_max + h * speed + h * h * self.gravity_norm    # how far a vertex can get this step
        phis, normals, vels, offsets = self.query(sim.x, t, np.inf if missed is not None else reach)
        margin = offsets + h * h * self.gravity_norm
        penetrating = np.any(phis < offsets, axis=0)
        exclude = self.never_contact | (self.released & ~penetrating)
        if missed is not None:
            exclude = exclude & ~missed.any(axis=0)
            margin = np.where(missed, np.inf, margin)
        frictions = np.array([c[1] for c in self.colliders])
        return detect(phis, normals, vels, sim.v, offsets, frictions, h, margin, exclude)

    def missed_contacts(self, result, h, missed):
        """(k, n_local) bool of free vertices ending deeper than MISSED_FRACTION d
        inside a collider without a contact constraint (accumulated over the
        passes), or None if there is none on any rank.  Collective."""
        sim = self.sim
        n, k = sim.n_owned, len(self.colliders)
        phis, _, _, offsets = self.query(result.x, sim.time + h, self.d_max)
        free = ~self.never_contact[:n]
        free[self.contacts.index[self.contacts.index < n]] = False
        deep = (offsets - phis > MISSED_FRACTION * offsets) & free[None]
        if sim.comm.max(np.array([float(deep.any())]))[0] == 0.0:
            return None
        flags = np.zeros((sim.n_local, k))
        flags[:n] = deep.T
        sim.ghosts.update(flags)
        new = flags.T > 0.5
        return new if missed is None else (new | missed)

    def response(self, result, h):
        """After the solve: friction (Coulomb, or Eq. 15 for image-space
        colliders) on the contacts, adhesive contacts marked for release, the
        position fail-safe, the Bridson pipeline for triangle contact.
        Collective."""
        from .collision.response import friction, normal_impulse
        sim = self.sim
        n = sim.n_owned
        x_new, v_new = result.x.copy(), result.v.copy()
        gain = getattr(sim.integrator, "position_gain", None) or h
        released = np.zeros((sim.n_local, 1))
        count = 0
        c = self.contacts
        if c is not None:
            mine = c.index < n
            idx = c.index[mine]
            count = int(idx.size)
            if idx.size:
                f0 = sim._first_forces if sim._first_forces is not None else np.zeros((sim.n_local, 3))
                normal = c.normal[mine]
                v_free = sim.v[idx] + h * f0[idx] / sim.mass[idx, None]
                dvn = normal_impulse(v_new[idx], v_free, normal)
                released[idx[dvn < 0.0], 0] = 1.0
                mu = c.friction[mine]
                image = np.array([self.colliders[j][3] == "image" for j in c.collider[mine]],
                                 dtype=bool)
                vf = v_new[idx].copy()
                # implicit schemes took it in the solve (physics/contact_friction.py)
                if not self.friction_in_solve and np.any(mu[~image] > 0):
                    vf[~image] = friction(v_new[idx][~image], c.velocity[mine][~image],
                                          normal[~image], mu[~image], dvn[~image])
                if image.any():      # seed 002 Eq. 15: C_fric keeps 1 - mu of the tangential velocity
                    from .collision.imagespace import velocity_response
                    vf[image] = velocity_response(v_new[idx][image], normal[image],
                                                  c.velocity[mine][image],
                                                  np.maximum(0.0, 1.0 - mu[image]), 0.0)
                x_new[idx] += gain * (vf - v_new[idx])
                v_new[idx] = vf
            sim.ghosts.update(released)
            self.pending_released = released[:, 0] > 0.5
        # the fail-safe before the triangle pipeline: its projection is then
        # part of the motion the CCD checks, so lifting a layer out of a body
        # cannot carry it through the layer above (it did, after the pipeline)
        pen, moved = -np.inf, 0
        if self.colliders:
            x_new, v_new, pen, moved = self._failsafe(x_new, v_new, h)
        if self.detector is not None:
            x_new, v_new = self._triangle_contact(x_new, v_new, h, gain)
        self.diag.update(contacts=count, max_penetration=pen, projected_vertices=moved)
        if self.self_collision:
            self.diag["self_intersections"] = float(self._count_crossings(x_new, sim.time + h))
        result.x, result.v = x_new, v_new
        return result

    def _triangle_contact(self, x_new, v_new, h, gain):
        """Bridson et al. 2002 on the all-gathered cloth plus the mesh
        colliders' vertices (infinite mass); every rank runs it on the same
        canonical candidates and keeps its own rows."""
        from .collision.impulses import ReusedCandidates, resolve
        sim, det = self.sim, self.detector
        n = sim.n_owned
        t0, t1 = sim.time, sim.time + h
        rows = det.gather(np.concatenate([sim.x[:n], x_new], axis=1))
        x0 = [rows[:, :3]]
        x1 = [rows[:, 3:]]
        for mesh in self.mesh_colliders:
            x0.append(mesh.vertices(t0))
            x1.append(mesh.vertices(t1))
        X0, X1 = np.concatenate(x0), np.concatenate(x1)
        U = (X1 - X0) / h
        inv_mass = np.zeros(X0.shape[0])
        free = ~self._pinned
        inv_mass[:det.geometry.n_cloth][free] = 1.0 / self._mass[free]
        g = det.geometry
        # one mu for the pipeline: the BVH mesh colliders' (plane quads leave
        # their friction to the contact constraints' Coulomb step)
        mu = max([c[1] for c in self.colliders if c[3] == "mesh"] + [0.0])
        found = ReusedCandidates(det.candidates, self.thickness, CANDIDATE_SLACK * self.thickness)
        U2, stats = resolve(X0, U, h, inv_mass, g.tri, g.edges, self.thickness, mu, found,
                            hits=det.shared_hits)
        mine = self._owned
        dU = U2[mine] - U[mine]
        x_new = x_new + h * dU
        v_new = v_new + dU * (h / gain)
        self.diag["impulse_hits"] = float(sum(stats.get("ccd_hits", [0])) if isinstance(
            stats.get("ccd_hits"), (list, tuple)) else stats.get("ccd_hits", 0))
        self.diag["impact_zone_vertices"] = float(stats.get("zone_vertices", 0))
        return x_new, v_new

    def _count_crossings(self, x_new, t1) -> int:
        """Cloth triangle pairs crossing at the end of the step (after the
        fail-safe: what the step hands on).  Collective."""
        det = self.detector
        X = np.concatenate([det.gather(x_new[:self.sim.n_owned])]
                           + [mesh.vertices(t1) for mesh in self.mesh_colliders])
        return det.count_intersections(X)

    def _failsafe(self, x_new, v_new, h):
        """Distance-field colliders at the end of the step: vertices inside
        moved out along n (inward relative normal velocity removed).  The
        penetration diagnostic is what the solve (and friction) left.
        Open meshes are left to the CCD pipeline (a distance cannot say on
        which side of a zero-thickness panel a vertex belongs)."""
        from .collision.response import project
        sim = self.sim
        n = sim.n_owned
        free = ~self.never_contact[:n]
        reach = self.d_max
        phis, normals, vels, offsets = self.query(x_new, sim.time + h, reach)
        pen = float(np.max((offsets - phis)[:, free], initial=-np.inf))
        moved = np.zeros(n, dtype=bool)
        for j, col in enumerate(self.colliders):
            if col[3] == "mesh" and not self._closed(j):
                continue
            if moved.any():     # an earlier collider's projection moved vertices: query again
                phis[j], normals[j], vels[j] = col[0](x_new, sim.time + h, reach)
            xs, vs, inside = project(x_new[free], v_new[free], phis[j][free], normals[j][free],
                                     vels[j][free], offsets[j][free])
            x_new[free], v_new[free] = xs, vs
            moved[np.nonzero(free)[0][inside]] = True
        return x_new, v_new, pen, int(moved.sum())

    def _closed(self, j) -> bool:
        q = self.colliders[j][0]
        return bool(getattr(getattr(q, "__self__", None), "closed", True))

    def accepted(self) -> None:
        if self.pending_released is not None:
            self.released = self.pending_released

    def diagnostics(self) -> dict:
        """Global counts and maxima (collective)."""
        sim = self.sim
        out = {}
        if self.colliders:
            d = self.diag
            sums = sim.comm.sum(np.array([float(d.get("contacts", 0)),
                                          float(d.get("projected_vertices", 0))]))
            pen = sim.comm.max(np.array([float(d.get("max_penetration", -np.inf))]))[0]
            out.update(contacts=sums[0], max_penetration=pen, projected_vertices=sums[1])
        if self.detector is not None:     # replicated values: the same on every rank
            out["impulse_hits"] = self.diag.get("impulse_hits", 0.0)
            out["impact_zone_vertices"] = self.diag.get("impact_zone_vertices", 0.0)
            if self.self_collision:
                out["self_intersections"] = self.diag.get("self_intersections", 0.0)
            out.update(self._traversal_diagnostics())
        return out

    def traversal_summary(self) -> str | None:
        """Collective: one line on the run's BVH traversals (load balance,
        stealing), for the log; None without a detector."""
        if self.detector is None:
            return None
        c = self.detector.counters
        comm = self.sim.comm
        busy = np.array([c["busy_time"]])
        bmax, bsum = comm.max(busy)[0], comm.sum(busy)[0]
        counts = comm.sum(np.array([c["tasks_created"], c["tasks_stolen"], c["steals_refused"],
                                    c["tests"]], dtype=np.float64))
        wall = comm.max(np.array([c["traverse_time"]]))[0]
        mean = bsum / comm.size
        ratio = bmax / mean if mean > 0 else 1.0
        mode = "stealing" if self.detector.stealing else "static"
        return (f"BVH traversal ({mode}): {c['refits']} phases, {wall:.2f} s wall, "
                f"busy max/mean {ratio:.2f}, {int(counts[3])} tests, {int(counts[0])} tasks "
                f"created, {int(counts[1])} stolen, {int(counts[2])} refused")

    def _traversal_diagnostics(self) -> dict:
        """The step's BVH traversal over the ranks (issue 5 instrumentation):
        busy is CPU time inside traversal chunks, not polling; the balance
        figure is traverse_busy_max / traverse_busy_mean."""
        st = self.detector.take_step_stats()
        comm = self.sim.comm
        mx = comm.max(np.array([st["busy"], st["wall"], st["latency_max"]]))
        sm = comm.sum(np.array([st["busy"], st["idle"], st["tests"], st["tasks_created"],
                                st["tasks_stolen"], st["steals_refused"], st["msgs_sent"]],
                               dtype=np.float64))
        p = comm.size
        return dict(traverse_wall=mx[1], traverse_busy_max=mx[0], traverse_busy_mean=sm[0] / p,
                    traverse_idle_mean=sm[1] / p, traverse_tests=sm[2], tasks_created=sm[3],
                    tasks_stolen=sm[4], steals_refused=sm[5], steal_messages=sm[6],
                    steal_latency_max=mx[2])


def _motion(spec):
    """The collider's keyframed rigid motion, or None."""
    from .collision.colliders import RigidMotion
    if spec.motion is None:
        return None
    return RigidMotion(spec.motion.times, spec.motion.translations, spec.motion.rotations)


def _plane_quad(spec, rest_positions):
    """A plane collider as a kinematic two-triangle quad for the triangle
    pipeline, far larger than the cloth (100 times its size plus 10 m), with
    the plane's motion.  Bridson et al. 2002 push bodies through the same
    impulses and impact zones as the cloth: a floor that only the contact
    constraints and the position fail-safe knew about let the fail-safe lift
    a layer of a pile through the layer above it (the ribbon of seed 000
    Fig. 19 reached the floor with over a hundred crossings)."""
    from .collision.colliders import MeshCollider, Plane
    rest = np.asarray(rest_positions, dtype=np.float64)
    corners, tris = Plane(**dict(spec.geometry)).quad(rest.mean(axis=0),
                                                      100.0 * float(np.ptp(rest, axis=0).max()) + 10.0)
    return MeshCollider(corners[None], tris, motion=_motion(spec),
                        friction=spec.friction, thickness=spec.thickness)
