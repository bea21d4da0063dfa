"""The preconditioners distcloth measures and offers by name: PETSc options
(without prefix, the scene's ``solver:``) and the matrix type they need (the
scene's ``linear_system.mat_type``).

The AMG settings are the best of a small sweep on the 100k-vertex case
(docs/benchmarks.md, scripts/bench_step.py): GAMG with one symmetric-SOR
sweep per level and a 0.02 aggregation threshold, hypre BoomerAMG with HMIS
coarsening and ext+i interpolation; both on AIJ (PETSc's GAMG cannot build
its graph from BAIJ). ``sgs32`` is the reference preconditioner of the EG07
tutorial, Part 1 §5.7, with a float32 matrix (distcloth/linalg/sgs32.py).
"""
from __future__ import annotations

PRECONDITIONERS = {
    # name: (solver options, linear_system.mat_type)
    "jacobi": ({"pc_type": "jacobi"}, "baij"),
    "bjacobi_sgs": ({"pc_type": "bjacobi", "sub_pc_type": "sor"}, "baij"),
    "sgs32": ({"pc_type": "python",
               "pc_python_type": "distcloth.linalg.sgs32.SinglePrecisionSGS"}, "baij"),
    "gamg": ({"pc_type": "gamg", "pc_gamg_reuse_interpolation": "true", "pc_gamg_threshold": 0.02,
              "mg_levels_ksp_type": "richardson", "mg_levels_pc_type": "sor",
              "mg_levels_ksp_max_it": 1}, "aij"),
    "hypre": ({"pc_type": "hypre", "pc_hypre_type": "boomeramg",
               "pc_hypre_boomeramg_coarsen_type": "HMIS", "pc_hypre_boomeramg_interp_type": "ext+i",
               "pc_hypre_boomeramg_P_max": 4, "pc_hypre_boomeramg_strong_threshold": 0.7}, "aij"),
}
