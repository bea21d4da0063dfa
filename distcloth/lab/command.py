"""``distcloth lab SCENE-OR-PRESET``: the command line of the fabric lab."""
from __future__ import annotations

import os
import shlex
import sys
import time

from ..config import format_config_error
from ..config.schema import ConfigError
from ..io.console import shared_or_refused
from . import RESOLUTIONS, TESTS
from .material import lab_material
from .report import PICTURES, SECTIONS


def add_arguments(p) -> None:
    p.add_argument("material", metavar="SCENE-OR-PRESET",
                   help="a fabric preset name, or a scene file whose piece gives the material")
    p.add_argument("--piece", default=None, help="with a scene: the piece whose material is "
                                                 "tested (default: the first)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a key of the material, e.g. bending_model=dihedral_shell "
                        "(checked like a scene's)")
    p.add_argument("--tests", nargs="+", default=list(TESTS), choices=list(TESTS),
                   metavar="TEST", help="tests to run (default: all): " + " ".join(TESTS))
    p.add_argument("--resolution", default="standard", choices=RESOLUTIONS,
                   help="specimen meshes: coarse (quick look) or standard (default)")
    p.add_argument("--output", default=None, metavar="REPORT.md",
                   help="write the report here (default: print it)")


def _header(material, args, comm, wall) -> str:
    command = "scripts/mpiexec.sh %d .venv/bin/distcloth lab %s" % (
        comm.size, " ".join(shlex.quote(a) for a in sys.argv[2:]))
    return "\n".join([f"## Fabric lab: {material.label}", "",
                      f"Material: `{material.raw}`; {args.resolution} specimens, "
                      f"{comm.size} rank(s), {wall:.1f} s.", "", "    " + command, ""])


def main(args, comm) -> int:
    material, message = None, None
    if comm.rank == 0:
        try:
            if args.output is not None and not args.output.endswith(".md"):
                raise ConfigError("--output", args.output, "a file name ending in .md")
            material = lab_material(args.material, args.piece, args.overrides)
        except ConfigError as exc:
            message = format_config_error(exc)
    material, code = shared_or_refused(comm, material, message)
    if code:
        return code
    t0 = time.perf_counter()
    sections = []
    for name in args.tests:
        if comm.rank == 0:
            print(f"[lab] {name}: {TESTS[name][0]}", file=sys.stderr, flush=True)
        result = TESTS[name][1].run(material.raw, material.base_dir, comm,
                                    resolution=args.resolution)
        sections.append(SECTIONS[name](result))
        if comm.rank == 0 and args.output and name in PICTURES and getattr(
                result, "shadow", None) is not None:
            picture = os.path.splitext(args.output)[0] + f"_{name}.png"
            os.makedirs(os.path.dirname(os.path.abspath(picture)), exist_ok=True)
            PICTURES[name](result, picture)
            sections[-1] += f"\n![{name}]({os.path.basename(picture)})\n"
    if comm.rank == 0:
        text = _header(material, args, comm, time.perf_counter() - t0) + "\n" + "\n".join(sections)
        if args.output:
            os.makedirs(os.path.dirname(os.path.abspath(args.output)), exist_ok=True)
            with open(args.output, "w", encoding="utf-8") as f:
                f.write(text)
            print(f"[lab] report: {os.path.abspath(args.output)}", file=sys.stderr)
        else:
            print(text)
    return 0
