"""Studies of the simulator itself, run as ``distcloth study NAME``.

Each study is a module with ``add_arguments(parser)`` and
``main(args, comm) -> exit status``; registering it here adds the
subcommand.
"""
from __future__ import annotations

import importlib

STUDIES = {
    "accuracy": ("the accuracy study: sweep settings, errors against a finer reference, "
                 "wall time and stage split, CSV + Markdown + plots", "distcloth.study.accuracy"),
    "stability": ("the stability suite: cases x integrators, a table of "
                  "survived / stopped / refused / FAILED", "distcloth.study.stability"),
}


def study_module(name: str):
    return importlib.import_module(STUDIES[name][1])


def add_study_parsers(study_parser) -> None:
    """One sub-subcommand per registered study."""
    sub = study_parser.add_subparsers(dest="study", required=True)
    for name, (help_, _) in STUDIES.items():
        p = sub.add_parser(name, help=help_, description=help_, allow_abbrev=False)
        study_module(name).add_arguments(p)


def run_study(args, comm) -> int:
    return study_module(args.study).main(args, comm)
