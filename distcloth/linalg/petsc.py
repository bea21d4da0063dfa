"""PETSc start-up and the options database (prefix ``distcloth_``).

Options come from two places: the scene's ``solver:`` section and the
command line.  The command line wins: a scene value is inserted only when the
command line did not set the same option.  Every option under the prefix
must be used by the time the solver is set up, otherwise it is a typo or a
setting for another solver type and the run is refused.  distcloth's own
settings written like options (``-distcloth_mat_type aij``) are taken out
first (:func:`take_options`): they go to the scene configuration.
"""
from __future__ import annotations

import ctypes
import sys
from collections.abc import Iterable

import petsc4py

from ..config.schema import OPTION_PREFIX as PREFIX

# Read by KSPSolve itself, after set-up: cannot be 'used' before the first solve.
SOLVE_TIME_OPTIONS = {
    "ksp_view", "ksp_view_pre", "ksp_converged_reason", "ksp_view_mat", "ksp_view_pmat",
    "ksp_view_rhs", "ksp_view_solution", "ksp_view_eigenvalues", "ksp_view_singularvalues",
    "ksp_view_final_residual", "ksp_view_mat_explicit", "ksp_view_preconditioned_operator_explicit",
    "ksp_compute_eigenvalues", "ksp_compute_singularvalues", "ksp_plot_eigenvalues",
    "ksp_converged_rate", "ksp_error_if_not_converged", "ksp_view_diagonal_scale",
}

# Options without the prefix that PETSc reads at start-up or at the end (logging,
# memory checks, error handling, the options files themselves): PetscOptionsUsed
# does not report them, and they are the only unprefixed options that mean
# anything to a run whose every PETSc object has the prefix.
GLOBAL_OPTIONS = {"help", "version", "info", "history", "log_view", "log_all", "log_trace",
                  "log_summary", "log_sync", "log_exclude", "log_include_actions",
                  "log_mpe", "log_perfstubs", "memory_view", "objects_dump", "options_left",
                  "options_file", "options_file_yaml", "options_string_yaml",
                  "options_monitor", "options_view", "skip_petscrc", "malloc", "malloc_debug",
                  "malloc_dump", "malloc_test", "malloc_view", "malloc_view_threshold",
                  "malloc_hbw", "malloc_coalesce", "malloc_requested_size", "on_error_abort",
                  "on_error_attach_debugger", "on_error_emacs", "start_in_debugger",
                  "stop_for_debugger", "debugger_ranks", "debugger_pause", "no_signal_handler",
                  "fp_trap", "check_pointer_intensity", "checkstack", "display", "nox",
                  "use_gpu_aware_mpi", "viewer_binary_skip_info", "omp_view_frequency",
                  "mpiuni-allow-multiprocess-launch"}
GLOBAL_PREFIXES = ("log_view", "malloc_", "info_", "options_", "debugger", "viewer_")
_initialised = False


def init_petsc(argv=None):
    """Initialise petsc4py with the PETSc options of the command line (once)."""
    global _initialised
    if not _initialised:
        petsc4py.init([sys.argv[0] if sys.argv else "distcloth"] + list(argv or []))
        _initialised = True
    return petsc()


def petsc():
    """The petsc4py.PETSc module (initialised without command-line options if
    ``init_petsc`` was not called first)."""
    # not imported at the top of any module: PETSc reads its command line when
    # it is first imported, so the command line can start it only if nothing
    # imported it before init_petsc
    from petsc4py import PETSc
    return PETSc


def libpetsc():
    """The PETSc shared library, for the few calls petsc4py 3.18 does not wrap."""
    petsc()      # loads the library first
    for name in ("libpetsc_real.so.3.18", "libpetsc_real.so", "libpetsc.so"):
        try:
            return ctypes.CDLL(name, mode=ctypes.RTLD_GLOBAL)
        except OSError:
            continue
    return None


def check_call(err: int, call: str) -> None:
    """Raise if a PETSc call made through ``libpetsc()`` returned an error code."""
    if err != 0:
        raise RuntimeError(f"{call} failed with PETSc error {err}")


def insert_scene_options(options: dict, from_command_line: set[str]) -> list[str]:
    """Put the scene's solver options into the database unless the command line
    set them; returns the names inserted, for ``remove_options`` when done."""
    PETSc = petsc()
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
    PETSc = petsc()
    db = PETSc.Options()
    for name in names:
        if db.hasName(name):
            db.delValue(name)


def take_options(names: Iterable[str]) -> dict[str, str]:
    """Remove ``-distcloth_<name>`` for each of ``names`` from the database and
    return what was given (name -> value text; a bare flag is 'true', as
    PETSc reads it)."""
    PETSc = petsc()
    db = PETSc.Options()
    given = db.getAll()
    taken = {}
    for name in names:
        if PREFIX + name in given:
            value = given[PREFIX + name]
            taken[name] = "true" if value is None else value
            db.delValue(PREFIX + name)
    return taken


def command_line_options() -> set[str]:
    """Names (without prefix) of the prefixed options present before the scene's are inserted."""
    PETSc = petsc()
    return {k[len(PREFIX):] for k in PETSc.Options().getAll() if k.startswith(PREFIX)}


def unused_options() -> list[str]:
    """Prefixed options nobody read (PetscOptionsUsed, through ctypes: petsc4py 3.18 lacks it)."""
    PETSc = petsc()
    lib = libpetsc()
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


def unused_unprefixed_options() -> list[str]:
    """Options without the prefix that are neither start-up options (GLOBAL_OPTIONS)
    nor read by any PETSc object: a distcloth solver option written without its
    prefix (-ksp_monitor), or a typo; PETSc would ignore them without a word."""
    PETSc = petsc()
    lib = libpetsc()
    used = ctypes.c_int(0)
    out = []
    for name in sorted(PETSc.Options().getAll()):
        if name.startswith(PREFIX) or name in GLOBAL_OPTIONS or name.startswith(GLOBAL_PREFIXES):
            continue
        if lib is not None and lib.PetscOptionsUsed(None, ("-" + name).encode(),
                                                     ctypes.byref(used)) == 0 and used.value:
            continue
        out.append(name)
    return out


def current_options(prefixed: bool = True) -> dict[str, str]:
    """Every option under the prefix now in the database (name without prefix ->
    value); ``prefixed=False``: every option without it."""
    PETSc = petsc()
    return {k[len(PREFIX):] if prefixed else k: v for k, v in PETSc.Options().getAll().items()
            if k.startswith(PREFIX) == prefixed}
