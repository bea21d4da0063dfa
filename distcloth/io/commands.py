"""The serial commands on a result file: ``distcloth export`` and ``distcloth view``.

They read the HDF5 file with h5py on one process (no MPI, no PETSc).  A bad
argument ends in one line naming it, the value and what is allowed, exit
status 2, and no file written.
"""
from __future__ import annotations

import argparse
import sys

from ..config import ConfigError, format_config_error
from .export import FORMATS, export
from .frames import FRAMES_HELP
from .viewer import write_viewer

COMMANDS = ("export", "view")


def add_result_parsers(sub) -> None:
    """Register ``export`` and ``view`` on the CLI's subparsers."""
    e = sub.add_parser("export", help="write a result's frames as OBJ / PLY meshes or a "
                                      "Blender point cache (PC2)",
                       allow_abbrev=False)
    _one_line_errors(e)
    e.add_argument("result", help="result file (.h5)")
    e.add_argument("--format", required=True, choices=FORMATS,
                   help="obj or ply: one mesh per frame; pc2: one point cache for Blender's "
                        "Mesh Cache modifier, plus the rest mesh as OBJ")
    e.add_argument("--frames", default="all", help=f"frames to write: {FRAMES_HELP} "
                                                   "(default: all)")
    e.add_argument("--output", help="obj/ply: a directory (default RESULT_obj/ beside the "
                                    "result), or a file for one frame; pc2: the .pc2 file "
                                    "(default RESULT.pc2)")
    e.add_argument("--overwrite", action="store_true", help="replace existing files")
    e.add_argument("--quiet", action="store_true", help="do not list the files written")
    v = sub.add_parser("view", help="write one HTML page that plays a result in the browser",
                       allow_abbrev=False)
    _one_line_errors(v)
    v.add_argument("result", help="result file (.h5)")
    v.add_argument("--output", help="the .html file (default: RESULT.html beside the result)")
    v.add_argument("--frames", default="all", help=f"frames to embed: {FRAMES_HELP} "
                                                   "(default: all)")
    v.add_argument("--overwrite", action="store_true", help="replace an existing page")
    v.add_argument("--quiet", action="store_true", help="do not print the page's path")


def _one_line_errors(parser: argparse.ArgumentParser) -> None:
    """argparse's usage errors as one line (the command's --help has the rest)."""
    def error(message: str):
        parser.exit(2, f"{parser.prog}: {message} (see {parser.prog} --help)\n")
    parser.error = error


def run_result_command(args) -> int:
    try:
        if args.command == "export":
            paths = export(args.result, args.format, args.frames, args.output, args.overwrite)
        else:
            paths = [write_viewer(args.result, args.output, args.frames, args.overwrite)]
    except ConfigError as exc:
        print(format_config_error(exc), file=sys.stderr, flush=True)
        return 2
    if not args.quiet:
        for path in paths:
            print(path)
    return 0
