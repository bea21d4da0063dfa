#!/usr/bin/env python3
"""Stop-and-go against Newton draping with Coulomb friction: the bundled
tablecloth on a sphere (configs/tablecloth_sphere.yaml, mu = 0.3).

    scripts/mpiexec.sh 2 .venv/bin/python scripts/drape_friction.py [--resolution 41] \
        [--tolerance 1e-4] [--stop-on kinetic] [--set KEY=VALUE ...]

Each method runs until the frictional residual (docs/drape.md: the largest
force on a vertex outside what pins, bodies and its friction cone hold, over
its weight) is below tolerance.  Prints per method the iterations, stops, CG
iterations, wall time, residual and potential energy, then how far the two
rest states are apart (rank 0, Markdown).
"""
import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def relax(method, stop_on, args, comm):
    """(table row, global positions in input order) of one drape."""
    from distcloth.config.load import load_config
    from distcloth.integrate.drape import Relaxation, relax_to_rest
    from distcloth.scene import build_model
    from distcloth.simulation import Simulation
    r = args.resolution
    cfg = load_config(str(ROOT / "configs" / "tablecloth_sphere.yaml"),
                      [f"cloth.0.mesh.grid.resolution=[{r}, {r}]", f"drape.method={method}",
                       f"drape.stop_on={stop_on}", f"drape.tolerance={args.tolerance:g}",
                       f"drape.max_iterations={args.max_iterations}", *args.set])
    model = build_model(cfg)
    sim = Simulation(cfg, model, comm, quiet=True)
    sim.prepare()
    relaxation = Relaxation(sim, cfg.drape)
    k, d, ksp, reason, wall = relax_to_rest(relaxation, args.max_iterations)
    if reason and comm.rank == 0:
        print(f"{method}: {reason}")
    x = np.zeros((model.num_vertices, 3))
    x[sim.layout.owned_input] = sim.owned_positions()
    x = comm.sum(x)
    name = method + (f" ({stop_on})" if method == "stop_and_go" else "")
    row = (name, k, relaxation.stops, ksp, wall, d["residual"], d["potential_energy"],
           d["touching"])
    sim.destroy()
    return row, x


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--resolution", type=int, default=41)
    ap.add_argument("--tolerance", type=float, default=1e-4)
    ap.add_argument("--max-iterations", type=int, default=5000)
    ap.add_argument("--stop-on", default="kinetic")
    ap.add_argument("--set", action="append", default=[], help="override a scene key")
    args = ap.parse_args()
    from distcloth.linalg.petsc import init_petsc
    init_petsc([])
    from distcloth.parallel.comm import Comm
    comm = Comm()
    rows, xs = [], []
    for method in ("stop_and_go", "newton"):
        row, x = relax(method, args.stop_on, args, comm)
        rows.append(row)
        xs.append(x)
    if comm.rank != 0:
        return
    print("| method | iterations | stops | CG iterations | wall s | residual | potential energy J "
          "| touching |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        print(f"| {r[0]} | {r[1]} | {r[2]} | {r[3]} | {r[4]:.1f} | {r[5]:.2e} | {r[6]:.6f} "
              f"| {r[7]} |")
    a, b = xs
    size = 1.0     # the tablecloth's side, m
    dist = np.linalg.norm(a - b, axis=1)
    print(f"\nrest states: RMS vertex distance {np.sqrt(np.mean(dist ** 2)) / size:.2e} of the "
          f"side, largest {dist.max() / size:.2e}; lowest points {a[:, 2].min():.4f} and "
          f"{b[:, 2].min():.4f} m; highest {a[:, 2].max():.4f} and {b[:, 2].max():.4f} m; "
          f"potential energy {abs(rows[0][6] - rows[1][6]) / rows[1][6]:.2e} apart (relative)")


if __name__ == "__main__":
    main()
