"""A running simulation as a checkpoint, and back: what a step depends on that
the scene does not give again.

That is the State (state.py) and the caches a step reads: the linear
solver's last solution (the initial guess of a warm start) and its solve
count (when the preconditioner is rebuilt), and for a sewn garment the
state the weld was made from (the welded mesh is rebuilt from it, so the
resumed run simulates the same topology).  Everything else is rebuilt
from the scene: the partition (any rank count may resume), the colliders
(their motion is a function of time), the force terms, the BVHs (refitted,
and the contact candidates are a canonical set), the energy guard's and
the strain limiter's settings.

Per-vertex arrays are gathered into *input* vertex order on every rank
(one all-gather) and scattered back to a new layout's local rows (owned and
ghosts: a ghost row is a copy of its owner's, so it is restored from it).
Bitwise continuation needs the preconditioner to be rebuilt at every solve
(linear_system.pc_rebuild_every: 1) and no preconditioner state carried
between solves (pc_gamg_reuse_interpolation); otherwise a resumed run
agrees within the solver's tolerance.
"""
from __future__ import annotations

import numpy as np

from .collision.response import Contacts
from .state import MultistepHistory

# per-vertex blocks of the gathered state: name -> columns
_VECTORS = ("x", "v", "acceleration", "history_x", "history_v", "solver_y",
            "contact_normal", "contact_velocity")
_CONTACT_VALUES = ("phi", "offset", "friction", "target")


def capture(sim, weld=None) -> tuple[dict, dict]:
    """(scalars, arrays) of ``sim`` in input vertex order, on every rank
    (collective).  ``weld``: (rows, t, step) a sewn garment was welded from."""
    state, lay, comm = sim.state, sim.layout, sim.comm
    n, nl = sim.n_owned, sim.n_local
    blocks: dict[str, np.ndarray] = {"x": state.x[:n], "v": state.v[:n]}
    if state.acceleration is not None:
        blocks["acceleration"] = state.acceleration[:n]
    if state.history is not None:
        blocks["history_x"], blocks["history_v"] = state.history.x[:n], state.history.v[:n]
    if state.touching is not None:
        blocks["touching"] = state.touching[:, :n].T.astype(np.float64)
    if state.contacts is not None:
        c = state.contacts
        collider = np.full(nl, -1.0)
        collider[c.index] = c.collider
        normal, velocity = np.zeros((nl, 3)), np.zeros((nl, 3))
        normal[c.index], velocity[c.index] = c.normal, c.velocity
        values = np.zeros((nl, len(_CONTACT_VALUES)))
        for j, name in enumerate(_CONTACT_VALUES):
            values[c.index, j] = getattr(c, name)
        blocks.update(contact_collider=collider[:n, None], contact_normal=normal[:n],
                      contact_velocity=velocity[:n], contact_values=values[:n])
    if sim.system is not None:
        blocks["solver_y"] = sim.system.y.array.reshape(-1, 3)
    names = list(blocks)
    widths = [blocks[k].reshape(n, -1).shape[1] for k in names]
    rows = np.hstack([blocks[k].reshape(n, -1) for k in names]) if n else np.zeros((0, sum(widths)))
    # every rank holds the same names: the blocks depend only on replicated state
    full = comm.allgather_rows(lay.owned_input, rows, sim.model.num_vertices)
    arrays, at = {}, 0
    for name, w in zip(names, widths):
        arrays[name] = full[:, at:at + w]
        at += w
    if "touching" in arrays:
        arrays["touching"] = arrays["touching"].T > 0.5
    if "contact_collider" in arrays:
        arrays["contact_collider"] = arrays["contact_collider"][:, 0].astype(np.int64)
    scalars = {"time": float(state.t), "step": int(state.step), "rejections": int(state.rejections),
               "newton_unconverged": int(state.newton_unconverged),
               "contact_changes": int(state.contact_changes),
               "limiter_unconverged_steps": int(sim.limiter_unconverged_steps)}
    if state.history is not None:
        scalars["history_h"] = float(state.history.h)
    if state.energy_reference is not None:
        scalars["energy_reference"] = np.array(state.energy_reference, dtype=np.float64)
    if state.step_error is not None:
        scalars["step_error"] = np.array(state.step_error, dtype=np.float64)
    if sim.system is not None:
        scalars["solver_solves"] = int(sim.system.solves)
    if weld is not None:
        rows_w, t_w, step_w = weld
        arrays["weld_rows"] = rows_w
        scalars.update(weld_time=float(t_w), weld_step=int(step_w))
    return scalars, arrays


def restore_state(sim, scalars: dict, arrays: dict) -> None:
    """Make ``sim``'s State the checkpoint's (before ``prepare``)."""
    state, lay = sim.state, sim.layout
    local = lay.local_input
    state.x[...] = arrays["x"][local]
    state.v[...] = arrays["v"][local]
    state.t, state.step = float(scalars["time"]), int(scalars["step"])
    state.rejections = int(scalars["rejections"])
    state.newton_unconverged = int(scalars["newton_unconverged"])
    state.contact_changes = int(scalars.get("contact_changes", 0))
    sim.limiter_unconverged_steps = int(scalars.get("limiter_unconverged_steps", 0))
    state.acceleration = arrays["acceleration"][local].copy() if "acceleration" in arrays else None
    state.history = None
    if "history_x" in arrays:
        state.history = MultistepHistory(arrays["history_x"][local].copy(),
                                         arrays["history_v"][local].copy(),
                                         float(scalars["history_h"]))
    state.touching = arrays["touching"][:, local].copy() if "touching" in arrays else None
    ref = scalars.get("energy_reference")
    state.energy_reference = None if ref is None else (float(ref[0]), float(ref[1]))
    err = scalars.get("step_error")
    state.step_error = None if err is None else (float(err[0]), float(err[1]))
    state.contacts = None
    if "contact_collider" in arrays:
        collider = arrays["contact_collider"][local]
        index = np.flatnonzero(collider >= 0)          # sorted local rows, as detection makes them
        values = arrays["contact_values"][local][index]
        state.contacts = Contacts(index.astype(np.int64), collider[index].astype(np.int64),
                                  arrays["contact_normal"][local][index],
                                  arrays["contact_velocity"][local][index],
                                  *(values[:, j].copy() for j in range(len(_CONTACT_VALUES))))


def restore_solver(sim, scalars: dict, arrays: dict) -> None:
    """The linear solver's caches (after ``prepare`` set the solver up)."""
    if sim.system is None or "solver_y" not in arrays:
        return
    sim.system.y.array[:] = arrays["solver_y"][sim.layout.owned_input].ravel()
    sim.system.solves = int(scalars.get("solver_solves", 0))
