"""Every bundled collision scene keeps every cloth vertex outside every
collider, at the end of every step, to within 10 % of the contact offset
d = cloth thickness + collider thickness (the piling ribbon: 90 %), on 2
ranks in process and on 1 rank through the CLI.

The scenes run coarser and shorter than shipped (the same colliders,
friction, thickness and step), long enough for the cloth to land: the
tablecloths on the (moving) sphere, the ribbon on its mesh ramps with
self-collision, the cloth on the torso mesh.  The oracle is the signed
distance of the end-of-step positions to each collider at the step's end
time, from a fresh collider object (analytic formula, or BVH closest point
with the pseudo-normal sign for the closed meshes), not the contact list of
the step.  On 1 rank every step is written as a frame and checked the same
way from the HDF5 file.
"""
from __future__ import annotations


import h5py
import numpy as np
import pytest

from conftest import ROOT, run_cli
from test_physics import gather_positions

# scene -> (overrides that make it small, end time s)
SCENES = {
    "tablecloth_sphere": (["cloth.0.mesh.grid.resolution=[15, 15]"], 0.5),
    "tablecloth_moving_sphere": (["cloth.0.mesh.grid.resolution=[15, 15]"], 0.5),
    "ribbon": (["cloth.0.mesh.grid.resolution=[11, 41]"], 0.4),
    "cloth_on_body": (["cloth.0.mesh.grid.resolution=[17, 17]"], 0.3),
}
# 10 % of d: the bound docs/collisions.md states for the bundled scenes; the
# ribbon piles up, and the triangle pipeline's impulses between its layers
# act after the fail-safe and can push the bottom layer into the ramp's
# offset, never into the ramp (docs/collisions.md, "The ribbon's pile"). How
# deep depends on the pile's path: 0.01-0.78 d over 2 ranks at 11 x 39, 41,
# 43 and 13 x 41, steps of 2.5, 4 and 5 ms, with the constraints' held
# directions scaled to their vertex or not (0.71 d at 11 x 39 without): 90 %
# of d there, short of the ramp itself
TOLERANCE = {"ribbon": 0.9}
DEFAULT_TOLERANCE = 0.1


def _config(name, extra=()):
    from distcloth.config.load import load_config
    over, end = SCENES[name]
    return load_config(str(ROOT / "configs" / f"{name}.yaml"),
                       [*over, f"time.end={end}", "output.preview=false", *extra])


def _oracle(cfg):
    """[(signed distance function (x, t) -> phi, d)] for the scene's colliders."""
    from distcloth.collision.colliders import (AnalyticCollider, Box, Capsule, Plane,
                                               RigidMotion, Sphere, load_mesh_collider)
    from distcloth.collision.mesh_query import MeshProximity
    thickness = max(c.thickness for c in cfg.cloth)
    out = []
    for spec in cfg.colliders:
        motion = None
        if spec.motion is not None:
            motion = RigidMotion(spec.motion.times, spec.motion.translations,
                                 spec.motion.rotations)
        d = thickness + spec.thickness
        if spec.shape == "mesh":
            prox = MeshProximity(load_mesh_collider(list(spec.files), frame_rate=spec.frame_rate,
                                                    motion=motion))
            assert prox.closed           # a signed distance needs an inside
            out.append((lambda x, t, p=prox: p.query(x, t)[0], d))
        else:
            shapes = {"plane": Plane, "sphere": Sphere, "capsule": Capsule, "box": Box}
            body = AnalyticCollider(shapes[spec.shape](**dict(spec.geometry)), motion, 0.0, 0.0)
            out.append((lambda x, t, b=body: b.query(x, t)[0], d))
    return out


def _worst(oracle, x, t):
    """Smallest (phi - d) / d over the colliders and vertices."""
    return min(float(np.min(phi(x, t) - d)) / d for phi, d in oracle)


@pytest.mark.parametrize("name", list(SCENES))
def test_scene_stays_outside_on_suite_ranks(name):
    from distcloth.linalg.petsc import init_petsc
    from distcloth.scene import build_model
    from distcloth.parallel.comm import Comm
    from distcloth.simulation import Simulation
    init_petsc([])
    cfg = _config(name)
    sim = Simulation(cfg, build_model(cfg), Comm(), quiet=True)
    sim.prepare()
    oracle = _oracle(cfg)
    worst, contacts = np.inf, 0.0
    n_steps = int(round(cfg.time.end / cfg.time.step))
    for _ in range(n_steps):
        diag = sim.step()
        contacts = max(contacts, diag["contacts"])
        worst = min(worst, _worst(oracle, gather_positions(sim), sim.state.t))
        if "self_intersections" in diag:
            assert diag["self_intersections"] == 0
    assert contacts > 0                      # the cloth did land
    assert worst >= -TOLERANCE.get(name, DEFAULT_TOLERANCE), worst


@pytest.mark.rank0_only
def test_scenes_stay_outside_on_one_rank(tmp_path):
    for name in SCENES:
        cfg = _config(name)
        out = tmp_path / f"{name}.h5"
        over, end = SCENES[name]
        args = ["run", str(ROOT / "configs" / f"{name}.yaml"), "--quiet", "--output", str(out)]
        for s in [*over, f"time.end={end}", "output.preview=false",
                  f"output.every={cfg.time.step}"]:
            args += ["--set", s]
        p = run_cli(args, ranks=1)
        assert p.returncode == 0, p.stderr
        oracle = _oracle(cfg)
        with h5py.File(out, "r") as f:
            k = int(f.attrs["frames_written"])
            times = f["frames/time"][:k]
            frames = f["frames/positions"][:k]
            assert k == int(round(end / cfg.time.step)) + 1
            assert np.nanmax(f["diagnostics/contacts"][:]) > 0
        worst = min(_worst(oracle, x, t) for x, t in zip(frames, times))
        assert worst >= -TOLERANCE.get(name, DEFAULT_TOLERANCE), (name, worst)
