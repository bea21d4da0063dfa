"""Shared fixtures.  The suite runs as ``mpiexec -n 2 python -m pytest``:
every test runs on every rank.  Tests that launch their own ``mpiexec``
run on rank 0 only (``rank0_only``), with the OMPI_*/PMIX_* variables of
this run removed from the child's environment."""
from __future__ import annotations

import os
import subprocess
import tempfile
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _rank_size():
    from mpi4py import MPI
    return MPI.COMM_WORLD.Get_rank(), MPI.COMM_WORLD.Get_size()


def pytest_configure(config):
    from mpi4py import MPI
    rank, _ = _rank_size()
    # each rank its own pytest temp dir below one fresh directory of this run:
    # concurrent pytest processes (ranks, other runs) must not clean up each other's
    if not config.option.basetemp:
        run_dir = tempfile.mkdtemp(prefix="distcloth-tests-") if rank == 0 else None
        run_dir = MPI.COMM_WORLD.bcast(run_dir, root=0)
        config.option.basetemp = f"{run_dir}/rank{rank}"
    config.addinivalue_line("markers", "rank0_only: launches subprocesses; runs on rank 0 only")


def pytest_collection_modifyitems(config, items):
    rank, _ = _rank_size()
    if rank != 0:
        skip = pytest.mark.skip(reason="launches its own processes: rank 0 runs it")
        for item in items:
            if "rank0_only" in item.keywords:
                item.add_marker(skip)


@pytest.hookimpl(trylast=True)
def pytest_runtest_teardown(item):
    """After a rank-0-only test the other ranks wait for rank 0 asleep: in the
    next test's first collective they would spin, taking a core from the
    test's own mpiexec job."""
    if "rank0_only" not in item.keywords:
        return
    import time
    from mpi4py import MPI
    if MPI.COMM_WORLD.Get_size() == 1:
        return
    request = MPI.COMM_WORLD.Ibarrier()
    while not request.Test():
        time.sleep(0.005)


@pytest.fixture(scope="session")
def comm():
    from mpi4py import MPI
    return MPI.COMM_WORLD


@pytest.fixture
def shared_tmp(comm, tmp_path):
    """A directory every rank agrees on (rank 0's tmp_path)."""
    return Path(comm.bcast(str(tmp_path), root=0))


def clean_env(**extra) -> dict:
    env = {k: v for k, v in os.environ.items()
           if not k.startswith(("OMPI_", "PMIX_", "PRTE_", "HYDRA_")) and k != "H5PY_ALWAYS_USE_MPI"}
    env.update({"OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1",
                "OMPI_MCA_mpi_yield_when_idle": "1", "OMPI_MCA_rmaps_base_oversubscribe": "1",
                # after a rank's non-zero exit mpiexec signals the job's other ranks and
                # waits this long before it kills them and exits itself: by default 1 s,
                # 1-2 s added to every child job that ends in an error, most of a
                # bad-input case's time.  Those ranks end on their own (the error is
                # agreed) and have written and printed all they will by then.  The test
                # of the one-second grace mpiexec gives a relayed SIGINT sets it back.
                "OMPI_MCA_odls_base_sigkill_timeout": "0",
                "PYTHONPATH": str(ROOT)})
    env.update(extra)
    return env


def run_cli(args, ranks: int | None = 2, timeout: float = 300, env_extra=None, cwd=None):
    """Run ``python -m distcloth ARGS`` under ``mpiexec -n ranks`` (or without
    mpiexec when ranks is None); returns the CompletedProcess."""
    cmd = [sys.executable, "-m", "distcloth", *map(str, args)]
    if ranks is not None:
        cmd = ["mpiexec", "--oversubscribe", "-n", str(ranks), *cmd]
    return subprocess.run(cmd, env=clean_env(**(env_extra or {})), cwd=cwd or ROOT,
                          capture_output=True, text=True, timeout=timeout)
