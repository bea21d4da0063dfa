"""Quasi-static loading of a specimen by its grips: one backward-Euler step
per load increment, so long (1 s) that inertia is negligible (M / h^2 is
1e-4 of the stiffness of any fabric) and the step is a static equilibrium,
with Newton iterations to convergence.  The grips move by keyframes, one key
per step."""
from __future__ import annotations

from typing import Callable

from ..config.load import config_from_dict
from ..inprocess import agreed, build_simulation
from ..simulation import SimulationError

STEP = 1.0          # s, one load increment


def time_settings(steps: int) -> dict:
    return {"end": STEP * steps, "step": STEP, "integrator": "backward_euler",
            "newton_iterations": 40, "newton_tolerance": 1e-10}


SOLVER = {"ksp_rtol": 1e-12, "ksp_norm_type": "unpreconditioned"}


def keyframes(values) -> list[float]:
    """Key times of a sweep: one per increment."""
    return [STEP * k for k in range(len(values))]


def sweep(raw: dict, name: str, base_dir: str, comm, steps: int,
          done: Callable[[dict], bool] | None = None) -> tuple[list[dict], str]:
    """Collective: every increment's diagnostics (the grips' reactions among
    them) and energies, until ``done(row)`` or the last increment; and why it
    stopped early ('' when it did not)."""
    sim, _, err = build_simulation(raw, name, comm, base_dir=base_dir)
    if err:
        return [], err
    rows = []
    try:
        for k in range(1, steps + 1):
            diag = sim.step()
            kinetic, gravitational, elastic = sim.energies()
            rows.append({**diag, "increment": k, "elastic_energy": elastic})
            if done is not None and done(rows[-1]):
                break
        return rows, ""
    except SimulationError as exc:
        return rows, str(exc)
    finally:
        sim.destroy()


def checked(raw: dict, name: str, base_dir: str, comm):
    """Collective: (the scene's config, '') or (None, the agreed refusal)."""
    cfg, err = agreed(comm, lambda: config_from_dict(raw, base_dir, name))
    return cfg, err or ""
