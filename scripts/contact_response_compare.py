#!/usr/bin/env python3
"""Contact constraints in the implicit solve against impulses after it.

Body contact can enter the solve as Baraff-Witkin constraints (what
distcloth does for distance-field colliders) or be answered by impulses
after the solve; this script measures both (the choice and its reasons:
docs/collisions.md).  Both variants here share everything but the contact
treatment:

* ``constraints``: the shipped pipeline (distcloth/collision/contact.py):
  predicted contacts constrain the normal velocity inside the solve, missed
  ones trigger a re-solve; Coulomb friction is a force of the solve
  (implicit schemes; after it for explicit ones), and a position fail-safe
  follows the solve.
* ``impulses``: no contact in the solve; after it, every vertex within d of
  a collider gets the inelastic normal impulse that cancels its approach,
  Coulomb friction bounded by mu times that impulse (Bridson et al. 2002
  §7.2-7.3) and is moved out to phi = d.

Cases (the scenes of tests/test_collisions.py): a cloth dropped on a sphere
(largest depth reached before the position fix, kinetic energy left once it
rests, steps/s) and a patch on a plane inclined at atan(mu) +- 5 degrees
(drift when it should stick, acceleration against g (sin - mu cos) when it
should slide).

    scripts/mpiexec.sh 2 .venv/bin/python scripts/contact_response_compare.py
"""
from __future__ import annotations

import math
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests"))
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import numpy as np  # noqa: E402

G = 9.81


def use_impulses(sim):
    """Swap the sim's contact treatment for post-solve impulses."""
    from distcloth.collision.contact import ContactReport, ContactResponse
    from distcloth.collision.response import Contacts, friction
    col = sim.contact
    stages = sim.pipeline.stages
    stages["collision:bodies"].fn = lambda state, h, missed=None: Contacts.none()
    col.missed_contacts = lambda contacts, x_end, t_end, missed: None

    def response(state, contacts, result, h):
        n = sim.n_owned
        x, v = result.x.copy(), result.v.copy()
        t1 = state.t + h
        phis, normals, vels, offs = col.query(x, t1, col.d_max)
        free = ~col.never_contact[:n]
        pen = float(np.max((offs - phis)[:, free], initial=-np.inf))
        count = 0
        for j, c in enumerate(col.colliders):
            inside = (phis[j] < offs[j]) & free
            if not inside.any():
                continue
            nrm, vb = normals[j][inside], vels[j][inside]
            dvn = np.maximum(-np.einsum("ni,ni->n", v[inside] - vb, nrm), 0.0)
            vn = v[inside] + dvn[:, None] * nrm
            vf = friction(vn, vb, nrm, np.full(dvn.size, c.friction), dvn)
            x[inside] += h * (vf - v[inside])        # backward Euler: x = x0 + h v
            v[inside] = vf
            ph, nr, _ = c.query(x[inside], t1, np.inf)
            x[inside] += np.maximum(offs[j][inside] - ph, 0.0)[:, None] * nr
            count += int(inside.sum())
        return ContactResponse(x, v, None, ContactReport(contacts=count, max_penetration=pen,
                                                         projected_vertices=count))
    stages["collision:response"].fn = response


def drop(variant):
    from test_collisions import drop_scene
    from test_physics import make_sim
    d = 0.002
    sim = make_sim(drop_scene({"name": "ball", "shape": "sphere", "center": [0, 0, 0],
                               "radius": 0.15, "friction": 0.3}, thickness=d))
    if variant == "impulses":
        use_impulses(sim)
    pens, kin = [], []
    t0 = time.perf_counter()
    for _ in range(200):
        diag = sim.step()
        pens.append(diag["max_penetration"])
        kin.append(diag["kinetic_energy"])
    wall = time.perf_counter() - t0
    return {"depth/d": max(pens) / d, "KE rest": float(np.max(kin[-50:])), "steps/s": 200 / wall}


def incline(variant, sign):
    """Stick drift (m) below atan mu, or the relative acceleration error above it."""
    from test_collisions import incline_scene
    from test_physics import gather_positions, make_sim
    mu, h = 0.4, 0.01
    theta = math.degrees(math.atan(mu)) + 5.0 * sign
    raw, down = incline_scene(theta, mu, h)
    sim = make_sim(raw)
    if variant == "impulses":
        use_impulses(sim)
    c0 = gather_positions(sim).mean(axis=0)
    s = [0.0]
    for _ in range(200):
        sim.step()
        s.append(float((gather_positions(sim).mean(axis=0) - c0) @ down))
    s = np.array(s)
    if sign < 0:
        return float(np.abs(s).max())
    th = math.radians(theta)
    expected = G * (math.sin(th) - mu * math.cos(th))
    t = h * np.arange(s.size)
    return 2.0 * np.polyfit(t, s, 2)[0] / expected - 1.0


def main():
    from mpi4py import MPI
    rows = []
    for variant in ("constraints", "impulses"):
        r = drop(variant)
        r["stick drift (m)"] = incline(variant, -1)
        r["slide accel. error"] = incline(variant, +1)
        rows.append((variant, r))
    if MPI.COMM_WORLD.Get_rank() != 0:
        return
    print(f"{MPI.COMM_WORLD.Get_size()} ranks; drop: 11 x 11 FE cloth on a sphere (r = 0.15 m, "
          f"d = 2 mm, 5 ms steps, 1 s); incline: 0.1 m patch, mu = 0.4, 10 ms steps, 2 s\n")
    print("| contacts as | depth before fix / d | kinetic energy at rest (J) | drop steps/s | "
          "drift below atan mu (m) | accel. error above atan mu |")
    print("|---|---:|---:|---:|---:|---:|")
    for v, r in rows:
        print(f"| {v} | {r['depth/d']:.3f} | {r['KE rest']:.2e} | {r['steps/s']:.1f} | "
              f"{r['stick drift (m)']:.1e} | {100 * r['slide accel. error']:+.2f} % |")


if __name__ == "__main__":
    main()
