#!/usr/bin/env python3
"""A garment scene on several rank counts: how far apart the results are.

    .venv/bin/python scripts/garment_rank_invariance.py [SCENE] [--ranks 1,2,3]
        [--set KEY=VALUE ...] [--keep DIR]

Runs ``distcloth run SCENE`` under ``scripts/mpiexec.sh N`` for every N
(default: configs/skirt_on_body.yaml to 0.7 s, the sewing phase and the
first steps of the welded garment) and prints, against the first rank
count, the largest vertex distance over the frames both wrote of the sewing file
(the panels' own meshes, input vertex order) and of the main file (the
welded garment), the step of the weld and the widest stitch at the weld.
The CG solve stops at a relative residual of 1e-5 and its iterates depend on
the partition, so rank counts agree to the solver's tolerance, not bit for
bit; the contact and self-collision decisions are made on the same data on
every rank count, so the difference must stay at that level and not grow.
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from distcloth.io.h5read import read_result  # noqa: E402


def run(scene: str, ranks: int, out: Path, sets: list[str]) -> float:
    cmd = [str(ROOT / "scripts" / "mpiexec.sh"), str(ranks), str(ROOT / ".venv" / "bin" / "python"),
           "-m", "distcloth", "run", scene, "--output", str(out), "--overwrite", "--quiet",
           "--set", "output.preview=false"]
    for s in sets:
        cmd += ["--set", s]
    env = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_"))}
    start = time.perf_counter()
    p = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True)
    if p.returncode != 0:
        sys.exit(f"{ranks} ranks failed ({p.returncode}):\n{p.stderr[-2000:]}")
    return time.perf_counter() - start


def frames(path: Path) -> tuple[np.ndarray, np.ndarray, dict]:
    r = read_result(path)
    return r["positions"], r["time"], r["diagnostics"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scene", nargs="?", default=str(ROOT / "configs" / "skirt_on_body.yaml"))
    ap.add_argument("--ranks", default="1,2,3")
    ap.add_argument("--set", action="append", default=None, dest="sets")
    ap.add_argument("--keep", default=None, help="folder for the result files")
    args = ap.parse_args()
    sets = args.sets if args.sets is not None else ["time.end=0.7"]
    counts = [int(r) for r in args.ranks.split(",")]
    folder = Path(args.keep or tempfile.mkdtemp(prefix="garment_ranks_"))
    folder.mkdir(parents=True, exist_ok=True)
    results = {}
    for n in counts:
        out = folder / f"ranks{n}.h5"
        wall = run(args.scene, n, out, sets)
        sew = frames(folder / f"ranks{n}_sewing.h5")
        main_ = frames(out)
        results[n] = (sew, main_, wall)
        d = sew[2]
        print(f"{n} ranks: {wall:.1f} s wall, weld at step {int(d['step'][-1])} "
              f"(t = {d['time'][-1]:.2f} s), widest stitch {1e3 * d['stitch_gap'][-1]:.3f} mm, "
              f"{main_[0].shape[1]} welded vertices, {main_[0].shape[0]} frames")
    ref = counts[0]
    for n in counts[1:]:
        for label, k in (("sewing", 0), ("welded", 1)):
            a, b = results[ref][k], results[n][k]
            # the frames both runs wrote (a weld one step apart shifts the
            # sewing file's last frame and the main file's times)
            ia, ib = np.nonzero(np.isclose(a[1][:, None], b[1][None, :], rtol=0.0,
                                           atol=1e-9))
            if a[0].shape[1:] != b[0].shape[1:] or ia.size == 0:
                print(f"{n} vs {ref} ranks, {label}: no common frame "
                      f"({a[0].shape} against {b[0].shape})")
                continue
            diff = np.linalg.norm(a[0][ia] - b[0][ib], axis=2).max(axis=1)
            times = " ".join(f"{t:.2f}:{d:.2g}" for t, d in zip(a[1][ia], diff))
            print(f"{n} vs {ref} ranks, {label}: largest vertex distance {diff.max():.3g} m "
                  f"(first frame {diff[0]:.3g}, last {diff[-1]:.3g}; {len(diff)} common "
                  f"frames; t [s]:distance [m] {times})")
    print(f"files in {folder}")


if __name__ == "__main__":
    main()
