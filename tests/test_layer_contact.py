"""Garments in layers meet the layers under them in the solve
(distcloth/collision/layers.py), as the innermost meets the body.

* the surface: distances, normals and velocities of an outer layer's
  vertices against the triangles of the layers under it, signed by the
  side the triangles face (unsigned beside its boundary), nothing for the
  inner layer's own vertices or before the surface is placed, its motion
  the start velocities';
* two sheets worn as layers over the torso mesh: the outer sheet's vertices
  become contacts of the solve against the inner one, resting on it they
  keep the thickness from it (by a distance of its own), no triangles
  cross, the energy guard never rejects a step, and 1 and 2 ranks agree
  while the layer contacts begin;
* the drapes' residual counts the outer sheet as supported by the inner one.
"""
import numpy as np
import pytest
from mpi4py import MPI

from distcloth.collision.layers import LayerSurface
from test_contact import ROOT
from test_physics import gather_positions, grid_scene, make_sim


def _plates():
    """Layer 0: the unit square at z = 0 (two triangles, vertices 0-3);
    layer 1: the same square at z = 0.01 (vertices 4-7)."""
    sq = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]])
    x = np.concatenate([sq, sq + [0, 0, 0.01]])
    tri = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    layer = np.array([0, 0, 0, 0, 1, 1, 1, 1])
    return x, tri, layer


def test_the_surface_answers_the_outer_layer_only():
    x, tri, layer = _plates()
    local = np.arange(8)
    s = LayerSurface(1, layer, local, tri)
    assert not s.empty
    np.testing.assert_array_equal(s.vertices, [0, 1, 2, 3])    # the outer plate is not in it
    phi, normal, vel = s.query(x, 0.0)
    assert np.all(np.isinf(phi))                                # not placed yet: no contact
    v = np.zeros_like(x)
    v[:4] = [0.0, 0.0, 0.2]                                     # the inner plate rises
    s.move(x, v, t=1.0)
    pts = x.copy()
    pts[4:, :2] = 0.25 + 0.5 * x[4:, :2]                        # over the plate's interior
    phi, normal, vel = s.query(pts, 1.0)
    assert np.all(np.isinf(phi[:4]))                            # the inner layer's own rows
    np.testing.assert_allclose(phi[4:], 0.01, rtol=1e-12)
    np.testing.assert_allclose(normal[4:], [[0, 0, 1]] * 4, atol=1e-12)
    np.testing.assert_allclose(vel[4:], [[0, 0, 0.2]] * 4, atol=1e-12)
    # through the step the surface moves on with its start velocities
    phi, _, _ = s.query(pts, 1.02)
    np.testing.assert_allclose(phi[4:], 0.01 - 0.2 * 0.02, rtol=1e-9)
    # the first rows only (a query of the owned rows of a rank)
    phi, _, _ = s.query(pts[:6], 1.0)
    assert phi.shape == (6,) and np.isinf(phi[:4]).all() and np.isfinite(phi[4:]).all()


def test_an_innermost_layer_has_no_surface_under_it():
    x, tri, layer = _plates()
    assert LayerSurface(0, layer, np.arange(8), tri).empty
    assert LayerSurface(1, np.zeros(8, int), np.arange(8), tri).empty


def _layered_sheets():
    def sheet(name, z, layer):
        return {"name": name, "mesh": {"grid": {"size": [0.5, 0.5], "resolution": [15, 15]},
                                       "center": [0.0, 0.0, z]},
                "material": {"model": "fem", "density": 0.15, "stretch": 100.0, "bending": 1e-5,
                             "damping": 0.002},
                "thickness": 0.003, "layer": layer}
    return grid_scene(
        cloth=[sheet("inner", 0.72, 0), sheet("outer", 0.74, 1)],
        effects=["gravity", "membrane", "bending", "damping", "collisions", "self_collision"],
        colliders=[{"name": "body", "shape": "mesh", "file": str(ROOT / "configs/meshes/torso.obj"),
                    "friction": 0.4}],
        time={"end": 0.5, "step": 0.005})


AGREE_STEPS = 28     # layer contacts from step 16 on


def _run_layers(comm, steps=100):
    sim = make_sim(_layered_sheets(), comm=comm)
    contact = sim.contact
    assert [c.kind for c in contact.colliders] == ["mesh", "layer"]
    assert [c.name for c in contact.bodies] == ["body"]
    surface = contact.layer_surfaces[0]
    n_inner = 15 * 15
    layer_contacts, crossings, closest, rejected = 0, 0.0, np.inf, 0
    for k in range(steps):
        diag = sim.step()
        crossings = max(crossings, diag["self_intersections"])
        rejected = diag["rejected_steps"]
        c = sim.state.contacts
        mine = (c.collider == 1) & (c.index < sim.n_owned)
        layer_contacts = max(layer_contacts, int(sim.comm.sum(np.array([float(mine.sum())]))[0]))
        # the outer sheet's distance to the inner one, measured from the
        # gathered positions (the inner sheet's triangles, a surface of its own)
        x = gather_positions(sim)
        if k == AGREE_STEPS - 1:
            early = x.copy()
        if k < steps - 30:                   # landed only in the last 30 steps
            continue
        probe = LayerSurface(1, np.repeat([0, 1], n_inner), np.arange(2 * n_inner),
                             sim.model.triangles)
        probe.move(x, np.zeros_like(x), sim.state.t)
        phi, _, _ = probe.query(x, sim.state.t)
        closest = min(closest, float(np.min(phi[n_inner:])))
    sim.destroy()
    assert surface.vertices.size == n_inner
    return early, layer_contacts, crossings, closest, rejected


@pytest.mark.parametrize("ranks", [1, 2])
def test_an_outer_layer_lies_on_the_inner_one_in_the_solve(ranks):
    comm = MPI.COMM_SELF if ranks == 1 else MPI.COMM_WORLD
    early, layer_contacts, crossings, closest, rejected = _run_layers(comm)
    assert layer_contacts > 20             # the outer sheet rests on the inner one in the solve
    assert crossings == 0
    # at rest the contact holds the outer sheet at d = 3 mm from the inner
    # one; the inner sheet moves through the step from where the surface
    # took it, and the contact set changes from step to step: measured 2.2
    # to 3.0 mm over the last 30 steps on 1 and 2 ranks.  With the triangle
    # pipeline alone, pushed out after every solve, it sat at 1.4 mm
    assert closest >= 0.65 * 0.003
    assert rejected == 0
    if ranks == 2:
        x1 = _run_layers(MPI.COMM_SELF, AGREE_STEPS)[0]
        # the same layer contacts on 1 and 2 ranks: positions within the
        # solver's tolerance (ksp_rtol 1e-12 in grid_scene) over the first 12
        # steps of them.  Not later: from the landing on, as on one layer,
        # contact decisions on positions that differ at round-off part the
        # runs by millimetres (docs/garments.md, rank invariance)
        np.testing.assert_allclose(early, x1, atol=1e-9)


def test_a_vertex_behind_the_layer_under_it_is_inside_it():
    # the inner plate's triangles face +z (counter-clockwise seen from above):
    # a vertex of the outer layer below it is behind it, phi < 0 with the
    # normal still towards the front; beside the plate's edge, where no side
    # is defined, the distance stays unsigned
    x, tri, layer = _plates()
    s = LayerSurface(1, layer, np.arange(8), tri)
    s.move(x, np.zeros_like(x), t=0.0)
    pts = x.copy()
    pts[4:] = [[0.5, 0.5, -0.002], [0.3, 0.6, 0.004], [1.01, 0.5, -0.001], [0.5, 0.5, 0.0]]
    phi, normal, _ = s.query(pts, 0.0)
    np.testing.assert_allclose(phi[4:6], [-0.002, 0.004], rtol=1e-9)
    np.testing.assert_allclose(normal[4:6], [[0, 0, 1], [0, 0, 1]], atol=1e-12)
    assert phi[6] == pytest.approx(np.hypot(0.01, 0.001), rel=1e-9)    # beside the edge
    assert phi[7] == 0.0 and np.allclose(normal[7], [0, 0, 1])        # on it: the front


def test_a_drape_residual_sees_the_outer_layer_resting_on_the_inner():
    # the drapes' residual (and the Newton drape's active set) ask the contact
    # which vertices a collider supports: the outer sheet's, resting on the
    # inner one, are supported by the layer under it once it is placed at the
    # state (ContactModel.place_layers), not only the inner sheet's by the body
    sim = make_sim(_layered_sheets(), comm=MPI.COMM_WORLD)
    for _ in range(60):
        sim.step()
    contact, state, n = sim.contact, sim.state, sim.n_owned
    contact.place_layers(state.x, state.v, state.t)
    touching, _, _, _ = contact.support(state.x, state.t, n)
    outer = np.asarray(contact.layer_surfaces[0].asks[:n])
    counts = sim.comm.sum(np.array([float((touching & outer).sum()),
                                    float((touching & ~outer).sum())]))
    sim.destroy()
    assert counts[0] > 20 and counts[1] > 20
