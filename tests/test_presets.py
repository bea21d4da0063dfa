"""The solver a scene gets: by problem size without a solver: section
(distcloth/linalg/presets.py), the scene's own with one."""
import pytest

from distcloth.linalg import presets
from distcloth.linalg.petsc import PREFIX
from test_physics import grid_scene, make_sim


@pytest.mark.parametrize("newton", [False, True])
@pytest.mark.parametrize("contact", [False, True])
@pytest.mark.parametrize("ranks", [1, 2, 3])
def test_by_size_switches_to_gamg_at_the_measured_crossover(ranks, contact, newton):
    table = presets.NEWTON_GAMG_FROM_VERTICES if newton else presets.GAMG_FROM_VERTICES
    at = table[min(ranks, 2)]
    if contact:
        at = max(at, presets.CONTACT_GAMG_FROM_VERTICES)
    assert presets.by_size(at - 1, ranks, contact, newton) == "bjacobi_sgs"
    assert presets.by_size(at, ranks, contact, newton) == "gamg"
    # more ranks never move the switch to larger problems, collisions never to
    # smaller, Newton-iterated steps (which share a set-up) never to larger
    assert table[2] <= table[1]
    assert presets.CONTACT_GAMG_FROM_VERTICES >= table[min(ranks, 2)]
    assert presets.NEWTON_GAMG_FROM_VERTICES[min(ranks, 2)] <= \
        presets.GAMG_FROM_VERTICES[min(ranks, 2)]


def test_the_peer_square_gets_gamg_when_its_steps_iterate_newton():
    # S1-41 (1,681 vertices, no collisions): one solve a step keeps block
    # Jacobi, Newton-iterated steps share a GAMG set-up and take GAMG
    n = 41 * 41
    for ranks in (1, 2):
        assert presets.choose({}, None, None, n, ranks).preset == "bjacobi_sgs"
        assert presets.choose({}, None, None, n, ranks, newton=True).preset == "gamg"
    # with collisions the contact passes' short solves keep block Jacobi
    assert presets.choose({}, None, None, n, 2, contact=True, newton=True).preset == \
        "bjacobi_sgs"


def test_the_peer_tablecloth_keeps_block_jacobi_and_the_square_of_its_size_does_not():
    # 81² = 6,561 vertices on two ranks: GAMG was 1.2x faster on the hanging
    # square and 1.46x slower on the tablecloth in contact with the sphere
    assert presets.choose({}, None, None, 81 * 81, 2).preset == "gamg"
    assert presets.choose({}, None, None, 81 * 81, 2, contact=True).preset == "bjacobi_sgs"
    assert presets.choose({}, None, None, 81 * 81, 1).preset == "bjacobi_sgs"


@pytest.mark.parametrize("ranks", [1, 2, 3])
def test_a_barrier_s_large_cloth_gets_gamg_smoothed_by_chebyshev(ranks):
    # contact as a barrier: the Chebyshev smoother's V-cycles took as many CG
    # iterations as SOR's at 20k-100k vertices and less time; with contact
    # as constraints it took half as many again, and without collisions
    # (the hanging square) 20-45 % more
    at = presets.CONTACT_GAMG_FROM_VERTICES
    assert presets.by_size(at - 1, ranks, contact=True, barrier=True) == "bjacobi_sgs"
    assert presets.by_size(at, ranks, contact=True, barrier=True) == "gamg_chebyshev"
    assert presets.by_size(at, ranks, contact=True) == "gamg"
    assert presets.by_size(10 ** 6, ranks, newton=True, barrier=True) == "gamg"
    choice = presets.choose({}, None, None, 317 * 317, ranks, contact=True, barrier=True)
    assert choice.options["mg_levels_ksp_type"] == "chebyshev"
    assert choice.mat_type == "aij" and choice.options["ksp_rtol"] == presets.CONTACT_RTOL
    # an explicit BAIJ matrix still forces block Jacobi
    assert presets.choose({}, "baij", None, 317 * 317, ranks, contact=True,
                          barrier=True).preset == "bjacobi_sgs"


def test_a_barrier_scene_reaches_gamg_smoothed_by_chebyshev(monkeypatch):
    # the crossover lowered to the 81-vertex tablecloth: contact as a barrier
    # gets the Chebyshev smoother and lands on the sphere with it (no step
    # refused, Newton converged in every step); as constraints, SOR's GAMG
    from test_barrier_contact import _sphere_scene
    for table in ("GAMG_FROM_VERTICES", "NEWTON_GAMG_FROM_VERTICES"):
        monkeypatch.setattr(presets, table, {1: 10, 2: 10})
    monkeypatch.setattr(presets, "CONTACT_GAMG_FROM_VERTICES", 10)
    raw = _sphere_scene(9, 0.02, 0.3)
    del raw["solver"]
    sim = make_sim(raw)
    try:
        assert sim.solver_choice.preset == "gamg_chebyshev"
        assert sim.system.ksp.getPC().getType() == "gamg"
        touching = max(sim.step()["contacts"] for _ in range(15))
        assert touching > 0 and sim.state.rejections == 0 and sim.state.newton_unconverged == 0
    finally:
        sim.destroy()
    raw["contact"] = {"model": "constraints"}
    sim = make_sim(raw)
    try:
        assert sim.solver_choice.preset == "gamg"
    finally:
        sim.destroy()


def test_choose_keeps_what_the_scene_says():
    own = presets.choose({"ksp_type": "cg", "pc_type": "jacobi"}, None, None, 10 ** 6, 2)
    assert own.preset is None and own.options["pc_type"] == "jacobi"
    assert own.mat_type == "baij" and own.warm_start is False
    # no solver: but an explicit BAIJ matrix: GAMG cannot take it
    baij = presets.choose({}, "baij", False, 10 ** 6, 2)
    assert baij.preset == "bjacobi_sgs" and baij.mat_type == "baij" and not baij.warm_start


def _solver(sim):
    ksp = sim.system.ksp
    return ksp.getPC().getType(), sim.system.mat_type, sim.system.warm_start, ksp.getTolerances()[0]


def test_a_scene_without_solver_gets_the_size_preset(monkeypatch):
    raw = grid_scene()
    del raw["solver"]
    sim = make_sim(raw)
    try:
        assert _solver(sim) == ("bjacobi", "baij", True, presets.DEFAULT_RTOL)
        assert sim.solver_choice.preset == "bjacobi_sgs"
    finally:
        sim.destroy()
    # the same 81-vertex scene above a (lowered) crossover: GAMG on AIJ
    monkeypatch.setattr(presets, "GAMG_FROM_VERTICES", {1: 10, 2: 10})
    sim = make_sim(raw)
    try:
        assert _solver(sim) == ("gamg", "aij", True, presets.DEFAULT_RTOL)
        sim.step()
    finally:
        sim.destroy()


@pytest.mark.parametrize("newton_iterations, preset", [(1, "bjacobi_sgs"), (3, "gamg")])
def test_the_scene_s_newton_iterations_reach_the_choice(monkeypatch, newton_iterations, preset):
    # the crossovers moved apart so that only the step's Newton iterations decide
    monkeypatch.setattr(presets, "GAMG_FROM_VERTICES", {1: 10 ** 6, 2: 10 ** 6})
    monkeypatch.setattr(presets, "NEWTON_GAMG_FROM_VERTICES", {1: 10, 2: 10})
    raw = grid_scene(time={"end": 0.02, "step": 0.01, "integrator": "bdf2",
                           "newton_iterations": newton_iterations})
    del raw["solver"]
    sim = make_sim(raw)
    try:
        assert sim.solver_choice.preset == preset
        assert sim.step()["newton_iterations"] >= 1
    finally:
        sim.destroy()


def test_an_explicit_solver_section_overrides_the_preset(monkeypatch):
    monkeypatch.setattr(presets, "GAMG_FROM_VERTICES", {1: 10, 2: 10})
    sim = make_sim(grid_scene(solver={"ksp_rtol": 1e-7, "pc_type": "jacobi"}))
    try:
        assert _solver(sim) == ("jacobi", "baij", False, 1e-7)
        assert sim.solver_choice.preset is None
    finally:
        sim.destroy()
    # and the scene's options are taken out again: the next scene gets its own
    from distcloth.linalg.petsc import petsc
    assert not petsc().Options().hasName(PREFIX + "pc_type")


def test_contact_scenes_keep_the_tighter_tolerance():
    # the penetration bounds of the collision tests were measured at 1e-5
    assert presets.choose({}, None, None, 1000, 1, contact=True).options["ksp_rtol"] == \
        presets.CONTACT_RTOL
    assert presets.choose({}, None, None, 1000, 1).options["ksp_rtol"] == presets.DEFAULT_RTOL
    assert presets.CONTACT_RTOL < presets.DEFAULT_RTOL


@pytest.mark.parametrize("preset", ["bjacobi_sgs", "gamg"])
def test_the_preset_tolerance_bounds_the_true_residual(monkeypatch, preset):
    # the preset's ksp_rtol is on |b - A dv| / |b| whatever the preconditioner:
    # on this stiff, lightly bent square each solve's true relative residual
    # (computed after the solve, diagnostics' ksp_residual) stays at or below
    # it.  On CG's default, the preconditioned residual, the same solves
    # stopped at true residuals up to 4.2e-2 (block Jacobi) and 1.8e-2 (GAMG)
    if preset == "gamg":
        monkeypatch.setattr(presets, "GAMG_FROM_VERTICES", {1: 10, 2: 10})
    raw = grid_scene(time={"end": 1.0, "step": 0.01, "integrator": "bdf2"})
    del raw["solver"]
    raw["cloth"][0]["mesh"]["grid"]["resolution"] = [17, 17]
    raw["cloth"][0]["material"].update(stretch=1000.0, shear=100.0)
    raw["cloth"][0]["pins"] = [{"edge": "top"}]
    sim = make_sim(raw)
    try:
        assert sim.solver_choice.preset == preset
        worst = max(sim.step()["ksp_residual"] for _ in range(30))
    finally:
        sim.destroy()
    # 1.0 + round-off: CG stops on its own recurrence's residual, which the
    # true one follows to ~1e-12 relative in double precision
    assert 0 < worst <= presets.DEFAULT_RTOL * (1.0 + 1e-6), worst


def test_contact_scenes_keep_cg_s_own_residual():
    # their 1e-5 was measured on it, and at 317² it is the cheaper one with
    # either contact model; an aimed solve needs |b - A dv| in contact too
    norm = "ksp_norm_type"
    assert presets.choose({}, None, None, 1000, 1).options[norm] == "unpreconditioned"
    assert norm not in presets.choose({}, None, None, 1000, 1, contact=True).options
    assert presets.choose({}, None, None, 1000, 1, contact=True, aimed=True).options[norm] == \
        "unpreconditioned"
    # a scene's own solver: section is taken as written
    assert norm not in presets.choose({"ksp_rtol": 1e-6}, None, None, 1000, 1).options
