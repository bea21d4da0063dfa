"""Command line: ``distcloth run|check SCENE.yaml [--output F] [--set k=v ...] [PETSc options]``,
``distcloth run SCENE.yaml --resume RESULT.h5``, ``distcloth inspect RESULT.h5`` (serial),
``distcloth study NAME [options]`` (distcloth/study/) and the serial tools on
a result file, ``distcloth export|view RESULT.h5 [options]`` (io/commands.py).

Arguments with a single leading dash (``-distcloth_ksp_rtol 1e-8``,
``-log_view``) are PETSc options and go to PETSc untouched; the command
line wins over the scene's ``solver:`` section.  The keys of the scene's
``linear_system:`` section are written the same way (``-distcloth_mat_type
aij``) but are scene settings: they are taken out of PETSc's options and
checked like ``--set linear_system.mat_type=aij``.
"""
from __future__ import annotations

import argparse
import os
import signal
import sys
import traceback

from .config import ConfigError, format_config_error, load_config
from .config.load import command_line_key, own_option_names
from .io.console import shared_or_refused
from .io.output_path import check_output_path
from .io.commands import COMMANDS as RESULT_COMMANDS, add_result_parsers, run_result_command
from .linalg.petsc import command_line_options, init_petsc, take_options
from .parallel.comm import Comm
from .run import drape, run
from .sew import sewing_path
from .lab.command import add_arguments as add_lab_arguments
from .lab.command import main as run_lab
from .study import add_study_parsers, run_study


def split_petsc_args(argv: list[str]) -> tuple[list[str], list[str]]:
    """Separate PETSc options (single dash + letter, with an optional value) from ours."""
    ours, petsc = [], []
    i = 0
    while i < len(argv):
        a = argv[i]
        if a.startswith("-") and not a.startswith("--") and len(a) > 1 and a[1].isalpha():
            petsc.append(a)
            if i + 1 < len(argv) and not _looks_like_option(argv[i + 1]) \
                    and not argv[i + 1].endswith((".yaml", ".yml")):
                petsc.append(argv[i + 1])
                i += 1
        else:
            ours.append(a)
        i += 1
    return ours, petsc


def _looks_like_option(s: str) -> bool:
    if not s.startswith("-"):
        return False
    try:
        float(s)
        return False
    except ValueError:
        return True


def _unreadable_options_file(petsc_args: list[str]) -> str | None:
    """The error line of an ``-options_file``/``-options_file_yaml`` argument that is
    not a readable file, or None."""
    for flag, value in zip(petsc_args, petsc_args[1:] + [None]):
        if flag in ("-options_file", "-options_file_yaml"):
            if value is None or value.startswith("-"):
                allowed, value = "a readable PETSc options file after it", None
            elif not os.path.isfile(value) or not os.access(value, os.R_OK):
                allowed = "a readable PETSc options file (" + (
                    "not found" if not os.path.exists(value) else "not a readable file") + ")"
            else:
                continue
            return format_config_error(ConfigError(f"command line {flag}", value, allowed))
    return None


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="distcloth", allow_abbrev=False,
                                description="Distributed cloth simulation on MPI and PETSc.",
                                epilog="PETSc options (single dash) pass through, e.g. "
                                       "-distcloth_ksp_rtol 1e-8 or -log_view.")
    sub = p.add_subparsers(dest="command", required=True)
    for name, help_ in (("run", "run a scene"), ("check", "validate a scene without running it"),
                        ("drape", "relax a scene to its rest state (drape: section of the scene)")):
        s = sub.add_parser(name, help=help_, allow_abbrev=False)
        s.add_argument("scene", help="scene YAML file")
        s.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                       help="override a config value (checked like the file), e.g. time.step=0.01")
        s.add_argument("--output", help="HDF5 output file (default: output.file of the scene)")
        s.add_argument("--overwrite", action="store_true",
                       help="replace the output file if it exists (refused otherwise)")
        if name in ("run", "drape"):
            s.add_argument("--quiet", action="store_true", help="no progress or summaries")
        if name == "run":
            s.add_argument("--force", action="store_true",
                           help="run an explicit step above the stability limit anyway")
            s.add_argument("--resume", metavar="RESULT.h5",
                           help="go on from the checkpoint of this result file (or from this "
                                "checkpoint), appending to the result; the scene must be the "
                                "one it was run with, time.end may grow")
    s = sub.add_parser("inspect", help="what a result file holds: scene, status, steps, "
                                       "stage times (serial, no mpiexec)", allow_abbrev=False)
    s.add_argument("result", help="HDF5 result file")
    s.add_argument("--plots", action="store_true", help="write the preview pictures again")
    add_study_parsers(sub.add_parser("study", help="studies of the simulator (accuracy "
                                                   "against time, stability suite)",
                                     allow_abbrev=False))
    lab = sub.add_parser("lab", help="the standard fabric tests (Peirce cantilever, Cusick "
                                     "drape, ...) on a preset or a scene's material",
                         allow_abbrev=False)
    add_lab_arguments(lab)
    add_result_parsers(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    ours, petsc_args = split_petsc_args(argv)
    args = build_parser().parse_args(ours)
    if args.command in RESULT_COMMANDS:     # serial tools on a result file: no PETSc
        if petsc_args:
            print(format_config_error(ConfigError(petsc_args[0], " ".join(petsc_args),
                                                  f"no PETSc options for distcloth "
                                                  f"{args.command}")), file=sys.stderr)
            return 2
        return run_result_command(args)
    if args.command == "inspect":
        # serial: imported here so that it starts neither PETSc nor MPI
        from .inspect import inspect
        return inspect(args.result, plots=args.plots)

    message = _unreadable_options_file(petsc_args)
    if message is not None:       # PETSc reads it on rank 0 only: the others would wait for it
        if Comm().rank == 0:
            print(message, file=sys.stderr, flush=True)
        return 2
    try:
        init_petsc(petsc_args)
    except Exception as exc:      # PETSc refused its command line, maybe on one rank only
        Comm().abort_with(format_config_error(ConfigError(
            "command line PETSc options", " ".join(petsc_args),
            f"options PETSc can read ({str(exc).strip()})")), 2)
    # out of the database before PETSc could report them as unused options
    own_options = take_options(own_option_names())
    comm = Comm()
    try:
        return _main(args, comm, command_line_options(), own_options)
    except SystemExit:
        raise
    except KeyboardInterrupt:   # Ctrl-C outside the steps (set-up, sewing): no traceback
        if comm.rank == 0:
            sys.stderr.write("[distcloth] interrupted (SIGINT) before the run could stop "
                             "cleanly: no checkpoint\n")
        if comm.size > 1:
            comm.abort(128 + signal.SIGINT)
        return 128 + signal.SIGINT
    except BaseException:  # a bug: never leave the other ranks waiting
        sys.stderr.write(f"[distcloth rank {comm.rank}] unexpected error:\n{traceback.format_exc()}")
        if comm.size > 1:
            comm.abort(1)
        return 1


def _main(args, comm, cmdline_options, own_options=None) -> int:
    if args.command in ("study", "lab"):     # no scene: it builds its own
        for name, value in (own_options or {}).items():
            if comm.rank == 0:
                print(format_config_error(ConfigError(
                    command_line_key(name), value, "a scene setting, given to a study as "
                    f"--set linear_system.{name}={value}" if args.command == "study" else
                    "a scene setting, not an option of distcloth lab")),
                    file=sys.stderr, flush=True)
            return 2
        return run_study(args, comm) if args.command == "study" else run_lab(args, comm)
    cfg, message = None, None
    if comm.rank == 0:
        try:
            cfg = load_config(args.scene, args.overrides, own_options)
            output = getattr(args, "output", None)
            if output is not None and not output.lower().endswith((".h5", ".hdf5")):
                raise ConfigError("--output", output, "a file name ending in .h5 or .hdf5")
            path = output or cfg.output.file
            # a garment being sewn also writes its sewing phase beside the result
            sewn = any(spec.mesh.pattern is not None for spec in cfg.cloth)
            # a resumed run appends to the result file it names (checked by run.py)
            resumed = getattr(args, "resume", None) is not None
            for p in [] if resumed else [path, sewing_path(path)] if sewn else [path]:
                # replacing an existing result: --overwrite
                check_output_path(p, "--output" if output else "output.file",
                                  replace=args.overwrite)
        except ConfigError as exc:
            message = format_config_error(exc)
    cfg, code = shared_or_refused(comm, cfg, message)
    if code:
        return code
    if args.command == "check":
        return run(cfg, comm, output=args.output, cmdline_options=cmdline_options,
                   check_only=True)
    if args.command == "drape":
        return drape(cfg, comm, output=args.output, cmdline_options=cmdline_options,
                     quiet=args.quiet)
    return run(cfg, comm, output=args.output, resume=args.resume, force=args.force,
               cmdline_options=cmdline_options, quiet=args.quiet)


if __name__ == "__main__":
    sys.exit(main())
