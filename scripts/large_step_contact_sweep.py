#!/usr/bin/env python3
"""Large implicit steps onto a body, with the energy guard on and no step
halving: the tablecloth on the sphere (1 m, 0.15 kg/m², FE membrane
1000 N/m, sphere r = 0.25 m and the floor, friction 0.3) at 15², 21² and
31², steps of 20 and 33 ms, grid_lines and dihedral bending, BDF-2 and
backward Euler, 1 s each (24 runs).  Prints for each run whether it
completed or at which step the guard stopped it, and the Newton iterations
per step (the energy retries' included), then how many completed.  A
change to the contact passes or to the retry's Newton shows here whether
it keeps large steps running (docs/integrators.md, "Large steps onto a
body").

    scripts/mpiexec.sh 2 .venv/bin/python scripts/large_step_contact_sweep.py
"""
from __future__ import annotations

import itertools
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from distcloth.inprocess import build_simulation  # noqa: E402
from distcloth.parallel.comm import Comm  # noqa: E402
from distcloth.simulation import SimulationError  # noqa: E402

END = 1.0


def scene(n: int, h: float, bending: str, integrator: str) -> dict:
    return {"scene": "large_steps_onto_a_sphere",
            "cloth": [{"name": "tablecloth",
                       "mesh": {"grid": {"size": [1.0, 1.0], "resolution": [n, n]},
                                "center": [0.0, 0.0, 0.6]},
                       "material": {"model": "fem", "density": 0.15, "stretch": 1000.0,
                                    "bending": 1.0e-6, "bending_model": bending}}],
            "effects": ["gravity", "membrane", "bending", "collisions"],
            "colliders": [{"name": "ball", "shape": "sphere", "center": [0.0, 0.0, 0.25],
                           "radius": 0.25, "friction": 0.3},
                          {"name": "floor", "shape": "plane", "normal": [0.0, 0.0, 1.0],
                           "offset": 0.0, "friction": 0.3}],
            "time": {"end": END, "step": h, "integrator": integrator},
            "solver": {"ksp_rtol": 1.0e-3},
            "output": {"file": "unused.h5", "every": END, "preview": False}}


def main() -> None:
    comm = Comm()
    completed = total = 0
    if comm.rank == 0:
        print("| n | h (ms) | bending | integrator | end | Newton its / step |")
        print("|---:|---:|---|---|---|---:|")
    for n, h, bending, integrator in itertools.product(
            (15, 21, 31), (0.02, 1.0 / 30.0), ("grid_lines", "dihedral"),
            ("bdf2", "backward_euler")):
        sim, _, err = build_simulation(scene(n, h, bending, integrator), "sweep", comm)
        if err:
            sys.exit(err)
        end, its = "completed", 0
        try:
            for _ in range(int(round(END / h))):
                its += sim.step()["newton_iterations"]
            completed += 1
        except SimulationError:
            end = f"stopped at step {sim.state.step}"
        total += 1
        if comm.rank == 0:
            print(f"| {n} | {h * 1e3:.3g} | {bending} | {integrator} | {end} | "
                  f"{its / max(sim.state.step, 1):.2f} |", flush=True)
        sim.destroy()
    if comm.rank == 0:
        print(f"completed {completed} of {total}")


if __name__ == "__main__":
    main()
