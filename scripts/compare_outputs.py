#!/usr/bin/env python3
"""Run every bundled scene at two commits and compare their HDF5 frames bit for bit.

    .venv/bin/python scripts/compare_outputs.py BEFORE AFTER [--ranks 2]
        [--scenes default,ribbon] [--set time.end=0.5] [--keep DIR]

Each commit is checked out into a temporary git worktree and run with Debian's
Python (``PYTHONPATH`` set to that worktree) under ``scripts/mpiexec.sh``;
AFTER may be ``WORKTREE`` for the uncommitted working tree, or a directory
holding a copy of the repository.  Prints, per scene,
whether ``/frames/positions`` and ``/frames/time`` are bitwise identical, the
largest position difference otherwise, the run status of each side, and the
per-step diagnostics that differ.  Exit status 0 only if every scene's frames
are identical.  A commit's outputs are cached under ``--keep`` by commit id, so
a later comparison against the same BEFORE reruns only AFTER.
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
PYTHON = "/usr/bin/python3"


def commit_id(ref: str) -> str:
    if ref == "WORKTREE":
        return "worktree"
    if os.path.isdir(ref):
        return "dir-" + Path(ref).resolve().name
    return subprocess.run(["git", "rev-parse", "--short=12", ref], cwd=ROOT, check=True,
                          capture_output=True, text=True).stdout.strip()


def checkout(ref: str, into: Path) -> Path:
    if ref == "WORKTREE":
        return ROOT
    if os.path.isdir(ref):
        return Path(ref).resolve()
    subprocess.run(["git", "worktree", "add", "--detach", "--force", str(into), ref], cwd=ROOT,
                   check=True, capture_output=True)
    return into


def run_scenes(tree: Path, scenes: list[str], ranks: int, sets: list[str], out: Path) -> None:
    env = {k: v for k, v in os.environ.items()
           if not k.startswith(("OMPI_", "PMIX_", "PRTE_"))}
    env["PYTHONPATH"] = str(tree)
    out.mkdir(parents=True, exist_ok=True)
    for scene in scenes:
        target = out / f"{scene}.h5"
        if target.exists():
            continue
        partial = out / f"{scene}.partial.h5"
        cmd = [str(ROOT / "scripts/mpiexec.sh"), str(ranks), PYTHON, "-m", "distcloth", "run",
               str(tree / "configs" / f"{scene}.yaml"), "--output", str(partial), "--overwrite", "--quiet",
               "--set", "output.preview=false"]
        for s in sets:
            cmd += ["--set", s]
        proc = subprocess.run(cmd, cwd=tree, env=env, capture_output=True, text=True)
        # exit 1 with a file: the run stopped numerically, which is a result to compare
        if proc.returncode not in (0, 1) or not partial.exists():
            sys.exit(f"{scene} at {tree}: exit {proc.returncode}\n{proc.stderr[-3000:]}")
        partial.rename(target)
        for side in (".partial.xdmf",):
            p = out / f"{scene}{side}"
            if p.exists():
                p.unlink()


def compare(a: Path, b: Path) -> tuple[bool, str]:
    import h5py
    with h5py.File(a, "r") as fa, h5py.File(b, "r") as fb:
        ka, kb = int(fa.attrs["frames_written"]), int(fb.attrs["frames_written"])
        xa, xb = fa["frames/positions"][:ka], fb["frames/positions"][:kb]
        ta, tb = fa["frames/time"][:ka], fb["frames/time"][:kb]
        status = f"status {fa.attrs.get('status')} / {fb.attrs.get('status')}"
        if ka != kb:
            return False, f"{ka} vs {kb} frames; {status}"
        same = np.array_equal(xa, xb) and np.array_equal(ta, tb)
        if same:
            text = f"identical ({ka} frames); {status}"
        else:
            text = f"DIFFER: max |dx| = {np.nanmax(np.abs(xa - xb)):.3g} m; {status}"
        diffs = []
        for name in sorted(set(fa["diagnostics"]) & set(fb["diagnostics"])):
            if not isinstance(fa["diagnostics"][name], h5py.Dataset) or name.startswith("stage"):
                continue
            da, db = fa["diagnostics"][name][:], fb["diagnostics"][name][:]
            if da.shape != db.shape or not np.array_equal(da, db, equal_nan=True):
                diffs.append(name)
        if diffs:
            text += "; diagnostics differing: " + ", ".join(diffs)
        return same, text


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("before")
    p.add_argument("after")
    p.add_argument("--ranks", type=int, default=2)
    p.add_argument("--scenes", default="", help="comma-separated scene names (default: every "
                                                "configs/*.yaml)")
    p.add_argument("--set", dest="sets", action="append", default=[], help="override for both")
    p.add_argument("--keep", default=str(ROOT / "out/compare"), help="where outputs are cached")
    args = p.parse_args()
    scenes = [s for s in args.scenes.split(",") if s] or sorted(
        f.stem for f in (ROOT / "configs").glob("*.yaml"))
    tag = f"n{args.ranks}" + "".join(f"_{s}" for s in args.sets).replace("/", "_")
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        for ref in (args.before, args.after):
            cid = commit_id(ref)
            out = Path(args.keep) / cid / tag
            if (cid == "worktree" or cid.startswith("dir-")) and out.exists():
                for f in out.glob("*.h5"):
                    f.unlink()
            tree = checkout(ref, Path(tmp) / cid)
            try:
                run_scenes(tree, scenes, args.ranks, args.sets, out)
            finally:
                if tree != ROOT and not os.path.isdir(ref):
                    subprocess.run(["git", "worktree", "remove", "--force", str(tree)], cwd=ROOT,
                                   capture_output=True)
            results[ref] = out
    ok = True
    for scene in scenes:
        same, text = compare(results[args.before] / f"{scene}.h5", results[args.after] / f"{scene}.h5")
        ok &= same
        print(f"{scene:28s} {text}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
