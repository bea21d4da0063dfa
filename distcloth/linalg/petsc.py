"""PETSc start-up and the options database (prefix ``distcloth_``).

Options come from two places: the scene's ``solver:`` section and the
command line.  The command line wins: a scene value is inserted only when the
command line did not set the same option.  Every option under the prefix
must be used by the time the solver is set up, otherwise it is a typo or a
setting for another solver type and the run is refused.
"""
from __future__ import annotations

import ctypes
import sys

PREFIX = "distcloth_"

# Read by KSPSolve itself, after set-up: cannot be 'used' before the first solve.
SOLVE_TIME_OPTIONS = {
    "ksp_view", "ksp_view_pre", "ksp_converged_reason", "ksp_view_mat", "ksp_view_pmat",
    "ksp_view_rhs", "ksp_view_solution", "ksp_view_eigenvalues", "ksp_view_singularvalues",
    "ksp_view_final_residual", "ksp_view_mat_explicit", "ksp_view_preconditioned_operator_explicit",
    "ksp_compute_eigenvalues", "ksp_compute_singularvalues", "ksp_plot_eigenvalues",
    "ksp_converged_rate", "ksp_error_if_not_converged", "ksp_view_diagonal_scale",
}

_initialised = False


def init_petsc(argv=None):
    """Initialise petsc4py with the PETSc options of the command line (once)."""
    global _initialised
    import petsc4py
    if not _initialised:
        petsc4py.init([sys.argv[0] if sys.argv else "distcloth"] + list(argv or []))
        _initialised = True
    from petsc4py import PETSc
    return PETSc


def _libpetsc():
    from petsc4py import PETSc  # noqa: F401  (loads the library first)
    for name in ("libpetsc_real.so.3.18", "libpetsc_real.so", "libpetsc.so"):
        try:
            return ctypes.CDLL(name, mode=ctypes.RTLD_GLOBAL)
        except OSError:
            continue
    return None


def insert_scene_options(options: dict, from_command_line: set[str]) -> list[str]:
    """Put the scene's solver options into the database unless the command line
    set them; returns the names inserted, for ``remove_options`` when done."""
    from petsc4py import PETSc
    db = PETSc.Options()
    inserted = []
    for key, value in options.items():
        if key in from_command_line:
            continue
        if isinstance(value, bool):
            value = "true" if value else "false"
        db.setValue(PREFIX + key, str(value))
        inserted.append(PREFIX + key)
    return inserted


def remove_options(names: list[str]) -> None:
    """Take a scene's options out again (dolfinx's rule: insert, apply, remove),
    so a later scene in the same process starts from the command line only."""
    from petsc4py import PETSc
    db = PETSc.Options()
    for name in names:
        if db.hasName(name):
            db.delValue(name)


def command_line_options() -> set[str]:
    """Names (without prefix) of the prefixed options present before the scene's are inserted."""
    from petsc4py import PETSc
    return {k[len(PREFIX):] for k in PETSc.Options().getAll() if k.startswith(PREFIX)}


def unused_options() -> list[str]:
    """Prefixed options nobody read (PetscOptionsUsed, through ctypes: petsc4py 3.18 lacks it)."""
    from petsc4py import PETSc
    lib = _libpetsc()
    if lib is None:
        return []
    used = ctypes.c_int(0)
    out = []
    for name in sorted(PETSc.Options().getAll()):
        if not name.startswith(PREFIX) or name[len(PREFIX):] in SOLVE_TIME_OPTIONS:
            continue
        err = lib.PetscOptionsUsed(None, name.encode(), ctypes.byref(used))
        if err == 0 and not used.value:
            out.append(name[len(PREFIX):])
    return out


def current_options() -> dict[str, str]:
    """Every option under the prefix now in the database (name without prefix -> value)."""
    from petsc4py import PETSc
    return {k[len(PREFIX):]: v for k, v in PETSc.Options().getAll().items() if k.startswith(PREFIX)}
