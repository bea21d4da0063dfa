#!/usr/bin/env python3
"""RMS vertex distance between two runs of the same scene at given times.

    .venv/bin/python scripts/run_distance.py A.h5 B.h5 [--times 0.5 1 1.5 2]

Prints, for each time, the RMS over vertices of |x_A - x_B| and their RMS
over the times (the error measure of docs/peers.md).  Both files are
`distcloth run` outputs of one scene (same vertex count and order) with a
frame at every time asked for.  Used to measure how far a converged run
moves when only the rank count or the solver tolerance changes: the floor
below which the peer comparison's errors cannot be told apart.
"""
from __future__ import annotations

import argparse
import sys

import h5py
import numpy as np


def frames_at(path: str, times) -> np.ndarray:
    with h5py.File(path, "r") as f:
        t = f["frames/time"][:]
        out = []
        for want in times:
            i = int(np.argmin(np.abs(t - want)))
            if abs(t[i] - want) > 1e-6:
                raise KeyError(f"{path}: no frame at t = {want:g} s (nearest {t[i]:g} s)")
            out.append(f["frames/positions"][i])
    return np.asarray(out)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("a")
    p.add_argument("b")
    p.add_argument("--times", type=float, nargs="+", default=[0.5, 1.0, 1.5, 2.0])
    a = p.parse_args(argv)
    try:
        A, B = frames_at(a.a, a.times), frames_at(a.b, a.times)
    except (OSError, KeyError) as exc:        # not a readable distcloth run output
        print(f"cannot read the runs' frames: {exc}", file=sys.stderr)
        return 2
    if A.shape != B.shape:
        print(f"the runs differ in shape: {A.shape} against {B.shape}", file=sys.stderr)
        return 2
    per = np.sqrt(np.mean(np.sum((A - B) ** 2, axis=2), axis=1))
    print("RMS distance mm: " + " / ".join(f"{1e3 * e:.1f}" for e in per)
          + f" at t = {' / '.join(f'{t:g}' for t in a.times)} s; "
          f"over the times {1e3 * np.sqrt(np.mean(per ** 2)):.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
