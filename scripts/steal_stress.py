#!/usr/bin/env python3
"""Stress test of the work-stealing traversal (distcloth/parallel/steal.py).

Runs N randomized small problems under the current mpiexec: random boxes in
a few random BVHs (random leaf sizes), the default root tests (every
object's self test, every pair's cross test), random rank ownership of the
root tests, random a, b, chunk, stealing on (mostly) or off, and random
injected delays.  Every rank builds the same problem from the problem's
seed.  For each problem it checks, against the serial ``run_tests``:

* deadlock: a watchdog (``run_tasks(timeout=...)`` plus a faulthandler
  timer that dumps every thread and exits if a blocking MPI call hangs);
* lost tests / rows: the union of the rows of all ranks equals the serial
  set, and the total number of tests executed equals the serial count;
* duplicated tests / rows: no row appears twice across ranks (the serial
  result has no duplicates, so the row count must match too).

    scripts/mpiexec.sh 4 .venv/bin/python scripts/steal_stress.py            # 1000 problems
    scripts/mpiexec.sh 3 .venv/bin/python scripts/steal_stress.py --n 30 --seed 7

Exit status 0 iff every problem passed; rank 0 prints one summary line.
"""
from __future__ import annotations

import argparse
import faulthandler
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from distcloth.collision.bvh import build_from_boxes  # noqa: E402
from distcloth.collision.traverse import (Forest, TraversalState, canonical,  # noqa: E402
                                          default_root_tests)
from distcloth.parallel.steal import StealTimeout, run_tasks  # noqa: E402


def random_problem(seed: int, size: int):
    """(forest, root tests, owner, run_tasks keyword arguments) of problem ``seed``."""
    rng = np.random.default_rng(seed)
    n_obj = int(rng.integers(1, 6))
    trees = []
    for _ in range(n_obj):
        m = int(rng.integers(0, 300)) if rng.random() < 0.95 else 0
        centre = rng.uniform(0, 1, 3)
        spread = rng.uniform(0.05, 0.6)
        c = centre + rng.normal(scale=spread, size=(m, 3))
        half = rng.uniform(0.0, 0.06, size=(m, 3)) * rng.uniform(0.2, 2.0)
        if m:
            trees.append(build_from_boxes(c - half, c + half, leaf_size=int(rng.integers(1, 9))))
    if not trees:
        c = rng.uniform(0, 1, (5, 3))
        trees.append(build_from_boxes(c - 0.1, c + 0.1))
    forest = Forest(trees)
    tests = default_root_tests(forest.n_objects)
    owner = rng.integers(0, size, tests.shape[0])
    if rng.random() < 0.3:                     # everything on one rank: all work must be stolen
        owner[:] = rng.integers(0, size)
    kw = dict(stealing=bool(rng.random() < 0.9),
              a=float(rng.choice([0.0, 0.5, 1.0, 2.0, 4.0])),
              b=float(rng.choice([0, 1, 2, 8, 32, 256, 10000])),
              chunk=int(rng.choice([1, 2, 7, 32, 256, 4096])),
              seed=seed)
    if rng.random() < 0.5:
        kw["delay"] = float(rng.uniform(0.0, 2e-3))
        kw["delay_prob"] = float(rng.uniform(0.05, 0.5)) * min(1.0, kw["chunk"] / 64)
    return forest, tests, owner, kw


def serial(forest, tests):
    st = TraversalState(tests)
    while st.top > 0:
        st.run(forest, 1 << 16)
    return st.pairs().copy(), st.tests_run


def main(argv=None) -> int:
    from distcloth.parallel.comm import Comm
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=1000, help="number of problems")
    ap.add_argument("--seed", type=int, default=0, help="first problem seed")
    ap.add_argument("--timeout", type=float, default=60.0, help="watchdog per problem (s)")
    args = ap.parse_args(argv)
    comm = Comm()
    rank, size = comm.rank, comm.size
    fails = {"deadlocks": 0, "lost_tests": 0, "dup_tests": 0, "lost_rows": 0, "dup_rows": 0,
             "wrong_rows": 0}
    totals = {"steals": 0, "refused": 0, "created": 0, "tests": 0, "msgs": 0}
    t_start = time.perf_counter()
    for i in range(args.n):
        seed = args.seed + i
        forest, tests, owner, kw = random_problem(seed, size)
        faulthandler.dump_traceback_later(args.timeout + 30, exit=True)
        try:
            rows, stats = run_tasks(comm, forest, tests, owner, timeout=args.timeout, **kw)
        except StealTimeout as e:
            print(f"[rank {rank}] DEADLOCK problem seed {seed} {kw}: {e}", flush=True)
            fails["deadlocks"] += 1
            time.sleep(3.0)                  # let the other ranks' watchdogs report too
            comm.abort(3)
        faulthandler.cancel_dump_traceback_later()
        gathered = comm.gather_objects((rows, stats))
        if rank != 0:
            continue
        ref, ref_tests = serial(forest, tests)
        allrows = np.concatenate([g[0] for g in gathered]).reshape(-1, 4)
        n_tests = sum(g[1]["tests"] for g in gathered)
        ref_c, got_c = canonical(ref), canonical(allrows)
        bad = []
        if n_tests < ref_tests:
            fails["lost_tests"] += 1
            bad.append(f"tests {n_tests} < {ref_tests}")
        if n_tests > ref_tests:
            fails["dup_tests"] += 1
            bad.append(f"tests {n_tests} > {ref_tests}")
        if allrows.shape[0] != got_c.shape[0]:
            fails["dup_rows"] += 1
            bad.append(f"{allrows.shape[0] - got_c.shape[0]} duplicated rows")
        if not np.array_equal(ref_c, got_c):
            if got_c.shape[0] < ref_c.shape[0]:
                fails["lost_rows"] += 1
            else:
                fails["wrong_rows"] += 1
            bad.append(f"rows {got_c.shape[0]} vs serial {ref_c.shape[0]}")
        if bad:
            print(f"FAIL problem seed {seed} {kw}: {'; '.join(bad)}", flush=True)
        totals["steals"] += sum(g[1]["tasks_stolen"] for g in gathered)
        totals["refused"] += sum(g[1]["steals_refused"] for g in gathered)
        totals["created"] += sum(g[1]["tasks_created"] for g in gathered)
        totals["tests"] += n_tests
        totals["msgs"] += sum(g[1]["msgs_sent"] for g in gathered)
    ok = None
    if rank == 0:
        wall = time.perf_counter() - t_start
        ok = not any(fails.values())
        print(f"steal_stress: {args.n} problems on {size} ranks in {wall:.1f} s: "
              + ", ".join(f"{k} {v}" for k, v in fails.items())
              + f" | tests {totals['tests']}, tasks created {totals['created']}, "
              f"stolen {totals['steals']}, refused {totals['refused']}, "
              f"messages {totals['msgs']} -> {'OK' if ok else 'FAILED'}", flush=True)
    ok = comm.broadcast(ok)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
