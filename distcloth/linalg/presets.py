"""The preconditioners distcloth measures and offers by name: PETSc options
(without prefix, the scene's ``solver:``) and the matrix type they need (the
scene's ``linear_system.mat_type``).

The AMG settings are the best of small sweeps on the 100k-vertex cloths
(docs/benchmarks.md, scripts/bench_step.py and scripts/bench_scale.py): GAMG
with one symmetric-SOR sweep per level and every coupling in its aggregation
graph (threshold 0: on a stiff membrane a threshold of 0.02 drops enough
couplings that GAMG coarsens by only 4 a level into dense coarse matrices,
operator complexity 2.2 against 1.09, and a solve in contact at 317² costs
30-40 % more); the same GAMG smoothed by Chebyshev on point-block Jacobi,
which the barrier's Newton solves take as few CG iterations with as with
SOR, for cheaper V-cycles (contact as constraints and the hanging square
took 20-50 % more); hypre BoomerAMG with HMIS coarsening and ext+i
interpolation; all on AIJ (PETSc's GAMG cannot build its graph from BAIJ).
``sgs32`` is the reference preconditioner of the EG07 tutorial, Part 1
§5.7, with a float32 matrix (distcloth/linalg/sgs32.py).
"""
from __future__ import annotations

from dataclasses import dataclass

PRECONDITIONERS = {
    # name: (solver options, linear_system.mat_type)
    "jacobi": ({"pc_type": "jacobi"}, "baij"),
    "bjacobi_sgs": ({"pc_type": "bjacobi", "sub_pc_type": "sor"}, "baij"),
    "sgs32": ({"pc_type": "python",
               "pc_python_type": "distcloth.linalg.sgs32.SinglePrecisionSGS"}, "baij"),
    "gamg": ({"pc_type": "gamg", "pc_gamg_reuse_interpolation": "true", "pc_gamg_threshold": 0.0,
              "mg_levels_ksp_type": "richardson", "mg_levels_pc_type": "sor",
              "mg_levels_ksp_max_it": 1}, "aij"),
    # GAMG smoothed by two Chebyshev iterations on 3x3 point-block Jacobi: a
    # V-cycle of matrix products, which at 20k-100k vertices run 2-2.5x the
    # flop rate of the SOR sweep (whose triangular solve is a chain of
    # dependent rows), at the bounds' safety factor 1.5 on the largest
    # eigenvalue of the Krylov estimate (1.2 gave an indefinite V-cycle on the
    # stiff hanging square; PETSc's 1.1 is lower still); the estimate is made
    # afresh at each set-up, as point-block Jacobi cannot reuse the aggregation's
    "gamg_chebyshev": ({"pc_type": "gamg", "pc_gamg_reuse_interpolation": "true",
                        "pc_gamg_threshold": 0.0, "mg_levels_ksp_type": "chebyshev",
                        "mg_levels_pc_type": "pbjacobi", "mg_levels_ksp_max_it": 2,
                        "mg_levels_ksp_chebyshev_esteig": "0,0.1,0,1.5"}, "aij"),
    "hypre": ({"pc_type": "hypre", "pc_hypre_type": "boomeramg",
               "pc_hypre_boomeramg_coarsen_type": "HMIS", "pc_hypre_boomeramg_interp_type": "ext+i",
               "pc_hypre_boomeramg_P_max": 4, "pc_hypre_boomeramg_strong_threshold": 0.7}, "aij"),
}


# The defaults of a scene that writes no solver: section, by problem size
# (docs/benchmarks.md, "Per-iteration overhead, ... and defaults by size";
# scripts/bench_defaults.py).  GAMG's few iterations pay for its set-up
# from GAMG_FROM_VERTICES[ranks] vertices on; below, block-Jacobi SGS on
# BAIJ is cheaper per step.  The grids' bending stiffness out of the plane
# is biharmonic, which block Jacobi's iterations grow with fastest.  Over
# whole 2 s runs of the stiff hanging square GAMG was 1.08-1.20x faster on
# two ranks from 71² (5,041 vertices) on, where its fewer iterations also
# save reductions, and tied on one rank up to 10k (0.89-0.99x); 1.9-2.3x
# faster at 20k on either.  A scene with collisions keeps block Jacobi below
# 10k: on S2-81 (6,561 vertices in contact) GAMG took 0.4x the CG
# iterations and 1.46x the time.  ksp_rtol: CG
# stops at 1e-3 of |b|, with the previous solve as the start (warm start):
# on the hanging square that moved positions by a few mm against a 1e-8
# solve, against 73 mm of time-stepping error at 5 ms, for half the CG
# iterations of 1e-3 from zero.
# The tolerance is on the unpreconditioned residual |b - A dv| / |b|, which
# means the same whatever the preconditioner (CG's default, the
# preconditioned residual, does not: at 1e-3 of it GAMG's solves on the stiff
# hanging square at 101² stopped farther from the solution than block
# Jacobi's, 83.5 against 63.0 mm of error over 2 s at 5 ms, for more time;
# on 41² with block Jacobi 46.6 against 38.3 mm).  PETSc's CG takes one norm
# an iteration either way: the unpreconditioned one costs nothing more.
# With collisions the contacts are constraints of the solve and the response
# after it starts from its result: at 1e-3 the piling ribbon's deepest
# penetration grew from within 70 % of the contact distance to 81 %
# (tests/test_scene_penetration.py), so contact scenes keep 1e-5, and of
# CG's own, preconditioned residual, which that was measured on: the stiff
# contact rows dominate |b - A dv|, and on it the tablecloth at 317² (GAMG)
# took 1.3x the step with contact as constraints and 1.6-1.9x as a barrier,
# S2-81's barrier 21 % more CG iterations (the walking dress and S2-81's
# constraints, block Jacobi, 7-8 % less time).  A solve aimed at the step's
# error (linear_system.step_error_fraction) needs the unpreconditioned one.
# Steps that iterate Newton set GAMG up once a step and keep it for the
# corrections (integrate/implicit.py), so its set-up is shared by two to
# four solves and it pays from smaller problems: on the stiff hanging square
# (BDF-2 10 ms, at most four Newton iterations), over whole 2 s runs, block
# Jacobi's stepping time was 0.99x GAMG's at 21² (441 vertices), 1.12x at
# 31² and 41², 1.5x at 61² on two ranks; 1.12x at 41², 1.29x at 61² on one
# (5 ms with two iterations: 1.12x at 41², 1.25x at 61², two ranks).
# With contact as a barrier, GAMG is smoothed by Chebyshev (gamg_chebyshev):
# on the tablecloth landing on the sphere (2 ranks) its V-cycle cost
# 0.55-0.65 of SOR's and the barrier's Newton solves took as many of them,
# 0.67x the step at 141², 0.90x at 201², 0.7-0.8x at 317² (0.77-0.96x over
# and after the landing), 0.73x at 1001²; with contact as constraints 1.5x
# the V-cycles and the same time, on the hanging square 20-45 % more CG
# iterations and 10-25 % more time.
GAMG_FROM_VERTICES = {1: 10000, 2: 5000}
NEWTON_GAMG_FROM_VERTICES = {1: 1600, 2: 900}
CONTACT_GAMG_FROM_VERTICES = 10000
DEFAULT_RTOL = 1.0e-3
CONTACT_RTOL = 1.0e-5


@dataclass(frozen=True)
class SolverChoice:
    """The solve a scene gets: PETSc options (without prefix), matrix type,
    warm start, and the preset's name if the problem size chose it."""
    options: dict
    mat_type: str
    warm_start: bool
    preset: str | None = None

    def describe(self) -> str:
        return f"{self.preset}, chosen by problem size" if self.preset else "the scene's solver:"


def by_size(n_vertices: int, ranks: int, contact: bool = False, newton: bool = False,
            barrier: bool = False) -> str:
    """The preconditioner (a PRECONDITIONERS name) for a cloth of this many
    vertices on this many ranks, in a scene with or without collisions (with
    contact as a ``barrier`` or not), whose steps iterate Newton (more than
    one solve a step) or not."""
    at = (NEWTON_GAMG_FROM_VERTICES if newton else GAMG_FROM_VERTICES)[min(ranks, 2)]
    if contact:
        at = max(at, CONTACT_GAMG_FROM_VERTICES)
    if n_vertices < at:
        return "bjacobi_sgs"
    return "gamg_chebyshev" if contact and barrier else "gamg"


def choose(solver: dict, mat_type: str | None, warm_start: bool | None,
           n_vertices: int, ranks: int, contact: bool = False,
           aimed: bool = False, newton: bool = False, barrier: bool = False) -> SolverChoice:
    """The scene's own ``solver:`` options if it wrote any (``solver`` not
    empty; then BAIJ and no warm start unless ``linear_system`` says so),
    else the preset by size, with CONTACT_RTOL if the scene has collisions,
    on the unpreconditioned residual without collisions or if a solve is
    ``aimed`` at the step's error.
    An explicit ``linear_system.mat_type`` is kept either way: BAIJ forces
    block-Jacobi SGS (GAMG needs AIJ)."""
    if solver:
        return SolverChoice(dict(solver), mat_type or "baij", bool(warm_start))
    name = by_size(n_vertices, ranks, contact, newton, barrier) if mat_type != "baij" \
        else "bjacobi_sgs"
    options, preset_mat = PRECONDITIONERS[name]
    rtol = CONTACT_RTOL if contact else DEFAULT_RTOL
    norm = {"ksp_norm_type": "unpreconditioned"} if aimed or not contact else {}
    return SolverChoice({"ksp_type": "cg", **options, "ksp_rtol": rtol, **norm},
                        mat_type or preset_mat, True if warm_start is None else warm_start, name)
