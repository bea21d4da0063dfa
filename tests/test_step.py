"""The step's structure: one declared stage list, run in its order; one State
that a rejected attempt leaves exactly as it was.

* the stages a step calls come in the order ``distcloth/stages.py`` declares,
  on an implicit scene with colliders, friction in the solve and
  self-collision (every stage kind);
* the documents generated from the stage list are current;
* a State snapshot restores every field;
* a step rejected by the energy guard and retried as two half steps ends
  bitwise where two plain half steps end: the rejected attempt left nothing
  behind (positions, velocities, time, contact memory).
"""
import numpy as np
import pytest

from distcloth import stages
from distcloth.state import MultistepHistory, State

from test_collisions import drop_scene
from test_physics import gather_positions, grid_scene, make_sim


def test_stages_run_in_the_declared_order():
    raw = drop_scene({"name": "ball", "shape": "sphere", "center": [0, 0, 0], "radius": 0.15,
                      "friction": 0.3})
    raw["effects"] = raw["effects"] + ["damping", "self_collision"]
    raw["cloth"][0]["material"]["damping"] = 0.001
    sim = make_sim(raw)
    sim.pipeline.trace = []
    for _ in range(30):           # falls onto the ball: contacts and friction by the end
        sim.step()
    sim.pipeline.trace = []
    sim.step()
    trace = sim.pipeline.trace
    first = list(dict.fromkeys(trace))
    order = [stages.STAGES.index(name) for name in first]
    assert order == sorted(order), first
    # everything this scene switches on ran in that one step (output is the run loop's)
    on = [n for n in sim.pipeline.names() if sim.pipeline.enabled(n) and n != "output"]
    assert set(on) <= set(trace)
    assert {"collision:bodies", "force:friction", "collision:response"} <= set(trace)
    # the integrator's stages come after the attempt's set-up, the response after the solve
    assert trace.index("collision:response") > max(i for i, n in enumerate(trace) if n == "solve")
    assert trace[-1] == "diagnostics"
    sim.destroy()


def test_stage_documents_are_current():
    assert stages.stale_files() == [], "run: python -m distcloth.stages --write"


def test_stage_declarations_are_complete():
    assert len(set(stages.STAGES)) == len(stages.STAGES)
    for s in stages.STEP_STAGES:
        assert s.when and s.reads and s.writes and s.doc, s.name
        # a force stage of an effect has its term's builder; a force stage of
        # no effect is built when the model holds its elements (stitches) or
        # by the contact model (friction); other stages of an effect (a
        # limiter) are bound by the simulation
        if s.name.startswith("force:"):
            assert s.effect is None or s.build is not None, s.name
        else:
            assert s.build is None, s.name
    assert stages.FORCE_STAGES == tuple(n for n in stages.STAGES if n.startswith("force:"))


def test_snapshot_restores_every_field():
    x, v = np.arange(12.0).reshape(4, 3), np.ones((4, 3))
    s = State(x=x, v=v, t=0.5, step=3, history=MultistepHistory(x.copy(), v.copy(), 0.1),
              energy_reference=(1.0, 2.0), rejections=1, newton_unconverged=2)
    saved = s.snapshot()
    s.x += 1.0
    s.v[:] = -5.0
    s.t, s.step, s.history, s.contacts = 0.6, 4, None, "contacts"
    s.energy_reference, s.rejections, s.newton_unconverged = None, 7, 9
    s.restore(saved)
    assert s.x is x and s.v is v                     # the same arrays, others hold them
    np.testing.assert_array_equal(s.x, np.arange(12.0).reshape(4, 3))
    np.testing.assert_array_equal(s.v, np.ones((4, 3)))
    assert (s.t, s.step, s.contacts, s.energy_reference, s.rejections,
            s.newton_unconverged) == (0.5, 3, None, (1.0, 2.0), 1, 2)
    assert s.history.h == 0.1


def _hanging(step, **time):
    # 9 x 9 sheet pinned along its top edge, one linearised backward-Euler step
    # of 0.1 s: the energy guard rejects it (tests/test_step_health.py) when it
    # is not solved again with Newton first
    raw = grid_scene(time={"end": 1.0, "step": step, "energy_retry_newton": 1, **time})
    raw["cloth"][0]["pins"] = [{"edge": "top"}]
    return raw


def test_a_rejected_attempt_leaves_nothing_behind():
    adaptive = make_sim(_hanging(0.1, adaptive=True, max_halvings=1))
    diag = adaptive.step()
    assert diag["rejected_steps"] == 1 and diag["step_size"] == pytest.approx(0.05)
    halves = make_sim(_hanging(0.05))
    halves.step()
    halves.step()
    # bitwise: the rejected attempt changed nothing the half steps read
    np.testing.assert_array_equal(gather_positions(adaptive), gather_positions(halves))
    n = adaptive.n_owned
    assert adaptive.state.t == halves.state.t == pytest.approx(0.1)
    assert adaptive.state.step == 1 and halves.state.step == 2
    va = adaptive.comm.sum(np.array([float(np.sum(adaptive.state.v[:n] ** 2))]))[0]
    vh = halves.comm.sum(np.array([float(np.sum(halves.state.v[:halves.n_owned] ** 2))]))[0]
    assert va == vh
    adaptive.destroy()
    halves.destroy()
