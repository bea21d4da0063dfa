"""Seam pucker against seam shrinkage: two 30 x 12 cm rectangles sewn along
their long sides (distcloth/garment/pucker.py), 1 s without gravity, for
each shrinkage; prints the amplitude and wavelength of the out-of-plane waves
along the seam and the run's wall time.

    .venv/bin/python scripts/pucker_study.py [--shrinkage 0 0.01 0.02 0.03 0.05]
"""
from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import h5py
import numpy as np
import yaml

from distcloth.config.load import config_from_dict
from distcloth.garment.pucker import pucker_pattern, pucker_scene, seam_waves
from distcloth.parallel.comm import Comm
from distcloth.run import run


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shrinkage", type=float, nargs="+", default=[0, 0.01, 0.02, 0.03, 0.05])
    args = parser.parse_args()
    comm = Comm()
    work = Path(tempfile.mkdtemp(prefix="pucker-"))
    (work / "p.yaml").write_text(yaml.safe_dump(pucker_pattern(), sort_keys=False))
    rows = []
    for s in args.shrinkage:
        out = work / f"o{s}.h5"
        cfg = config_from_dict(pucker_scene(str(work / "p.yaml"), s, str(out)), str(work), "p")
        t0 = time.perf_counter()
        assert run(cfg, comm, quiet=True, progress=False) == 0
        wall = time.perf_counter() - t0
        with h5py.File(out, "r") as f:
            x = f["frames/positions"][-1]
            seam = np.unique(f["garment/seam_lines"][:])
        amp, wave, changes = seam_waves(x, seam[np.argsort(x[seam, 1])])
        rows.append((s, amp, wave, changes, float(np.ptp(x[:, 2])), wall))
    if comm.rank == 0:
        print("| shrinkage | amplitude along the seam (mm) | wavelength (cm) | sign changes "
              "| out-of-plane extent of the panels (mm) | wall (s) |")
        print("|---:|---:|---:|---:|---:|---:|")
        for s, amp, wave, changes, extent, wall in rows:
            print(f"| {100 * s:g} % | {1e3 * amp:.2f} | {100 * wave:.1f} | {changes} | "
                  f"{1e3 * extent:.1f} | {wall:.1f} |")


if __name__ == "__main__":
    main()
