"""Command line: ``distcloth run|check SCENE.yaml [--output F] [--set k=v ...] [PETSc options]``,
``distcloth run SCENE.yaml --resume RESULT.h5``, ``distcloth inspect RESULT.h5`` (serial)
and ``distcloth study NAME [options]`` (distcloth/study/).

Arguments with a single leading dash (``-distcloth_ksp_rtol 1e-8``,
``-log_view``) are PETSc options and go to PETSc untouched; the command
line wins over the scene's ``solver:`` section.  The keys of the scene's
``linear_system:`` section are written the same way (``-distcloth_mat_type
aij``) but are scene settings: they are taken out of PETSc's options and
checked like ``--set linear_system.mat_type=aij``.
"""
from __future__ import annotations

import argparse
import signal
import sys
import traceback

from .config import ConfigError, format_config_error, load_config
from .config.load import command_line_key, own_option_names
from .linalg.petsc import command_line_options, init_petsc, take_options
from .parallel.comm import Comm
from .run import drape, run
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
        if name in ("run", "drape"):
            s.add_argument("--output", help="HDF5 output file (default: output.file of the scene)")
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
    return p


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    ours, petsc_args = split_petsc_args(argv)
    args = build_parser().parse_args(ours)
    if args.command == "inspect":
        # serial: imported here so that it starts neither PETSc nor MPI
        from .inspect import inspect
        return inspect(args.result, plots=args.plots)

    init_petsc(petsc_args)
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
    if args.command == "study":          # no scene: the study builds its own
        for name, value in (own_options or {}).items():
            if comm.rank == 0:
                print(format_config_error(ConfigError(
                    command_line_key(name), value, "a scene setting (linear_system): "
                    "not taken by distcloth study")), file=sys.stderr, flush=True)
            return 2
        return run_study(args, comm)
    cfg, message = None, None
    if comm.rank == 0:
        try:
            cfg = load_config(args.scene, args.overrides, own_options)
            output = getattr(args, "output", None)
            if output is not None and not output.lower().endswith((".h5", ".hdf5")):
                raise ConfigError("--output", output, "a file name ending in .h5 or .hdf5")
        except ConfigError as exc:
            message = format_config_error(exc)
    cfg, message = comm.broadcast((cfg, message))
    if message is not None:
        if comm.rank == 0:
            print(message, file=sys.stderr, flush=True)
        return 2
    if args.command == "check":
        return run(cfg, comm, cmdline_options=cmdline_options, check_only=True)
    if args.command == "drape":
        return drape(cfg, comm, output=args.output, cmdline_options=cmdline_options,
                     quiet=args.quiet)
    return run(cfg, comm, output=args.output, resume=args.resume, force=args.force,
               cmdline_options=cmdline_options, quiet=args.quiet)


if __name__ == "__main__":
    sys.exit(main())
