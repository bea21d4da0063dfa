#!/usr/bin/env python3
"""The full stability suite: every case at full size (the long run
10,000 steps) x every integrator, under the settings below, on 2 MPI ranks;
writes docs/stability.md (tables, criteria, a paragraph per case, the
machine) and docs/stability.csv (one row per variant).

    .venv/bin/python scripts/stability_suite.py [--ranks N] [--output F.md] [study options]

It runs

    scripts/mpiexec.sh 2 .venv/bin/python -m distcloth study stability \\
        --settings case_step newton mass_spring explicit_stable explicit_forced \\
        --output docs/stability.md

and then lists the FAILED variants from the CSV. About 35 minutes on the
2-core Debian 12 VM (docs/stability.md records the time of the committed run).
Extra options (--cases, --integrators, --settings, --reduced) go to the command.
"""
from __future__ import annotations

import argparse
import csv
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SETTINGS = ["case_step", "newton", "mass_spring", "explicit_stable", "explicit_forced"]


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--ranks", type=int, default=2)
    p.add_argument("--output", default="docs/stability.md")
    args, extra = p.parse_known_args()
    if "--settings" not in extra:
        extra = ["--settings", *SETTINGS, *extra]
    python = str(ROOT / ".venv" / "bin" / "python")
    cmd = [str(ROOT / "scripts" / "mpiexec.sh"), str(args.ranks), python,
           "-m", "distcloth", "study", "stability", *extra, "--output", args.output]
    print(" ".join(cmd), flush=True)
    code = subprocess.call(cmd, cwd=ROOT)
    csv_path = ROOT / (os.path.splitext(args.output)[0] + ".csv")
    if code == 0 and csv_path.exists():
        with open(csv_path, newline="", encoding="utf-8") as f:
            rows = list(csv.DictReader(f))
        counts = {}
        for r in rows:
            counts[r["status"]] = counts.get(r["status"], 0) + 1
        print(f"{len(rows)} variants: " + ", ".join(f"{n} {s}" for s, n in sorted(counts.items())))
        for r in rows:
            if r["status"] == "FAILED":
                print(f"  FAILED {r['case']} / {r['integrator']} / {r['setting']}: "
                      f"step {r['step']}: {r['reason']}")
    return code


if __name__ == "__main__":
    sys.exit(main())
