"""Checkpoint, interruption and resume, end to end through the command line:
a small cloth falling onto a sphere and the floor (contacts, friction in the
solve and BDF-2's history all carried by the State), interrupted at a random
step and resumed on the same rank count (bitwise the uninterrupted run) and
on another (within the solver's tolerance); killed, and resumed from the
last checkpoint; ``distcloth inspect``."""
from __future__ import annotations

import os
import random
import shutil
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from conftest import clean_env, run_cli
from distcloth.io.checkpoint import checkpoint_path, read_checkpoint
from distcloth.io.h5read import read_attrs, read_result

pytestmark = pytest.mark.rank0_only

SCENE = """\
scene: tiny_sphere
cloth:
  - name: sheet
    mesh:
      grid: {size: [0.6, 0.6], resolution: [9, 9]}
      center: [0.0, 0.0, 0.53]
    material: {model: mass_spring, density: 0.15, stretch: 100.0, shear: 10.0,
               bending: 1.0e-5, damping: 0.002}
    thickness: 0.004
effects: [gravity, membrane, bending, damping, collisions]
colliders:
  - {name: ball, shape: sphere, center: [0.0, 0.0, 0.25], radius: 0.25, friction: 0.3}
  - {name: floor, shape: plane, normal: [0.0, 0.0, 1.0], offset: 0.0, friction: 0.3}
time: {end: 0.3, step: 0.005, integrator: bdf2}
solver: {ksp_rtol: 1.0e-5}
output: {file: out.h5, every: 0.05, preview: false}
"""
STEPS = 60
SEED = int.from_bytes(os.urandom(4), "little")
RNG = random.Random(SEED)
# the diagnostics that are wall-clock times differ between any two runs
TIMINGS = ("traverse_wall", "traverse_busy_max", "traverse_busy_mean", "traverse_idle_mean",
           "steal_latency_max")


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    d = tmp_path_factory.mktemp("restart")
    (d / "scene.yaml").write_text(SCENE)
    ref = d / "ref" / "out.h5"
    r = cli(d, "run", "scene.yaml", "--output", ref)
    assert r.returncode == 0, r.stderr
    return {"dir": d, "ref": read_result(ref), "ref_path": ref}


def cli(d, *args, ranks=2, env=None):
    return run_cli([*args, "--quiet"] if args[0] == "run" else args, ranks=ranks,
                   env_extra=env, cwd=d, timeout=120)


def same_run(res, ref):
    """Bitwise the same frames and (timing aside) diagnostics."""
    assert np.array_equal(res["step"], ref["step"])
    assert np.array_equal(res["positions"], ref["positions"])
    for name, values in ref["diagnostics"].items():
        if name not in TIMINGS:
            assert np.array_equal(res["diagnostics"][name], values, equal_nan=True), name


def no_traceback(r):
    assert "Traceback" not in r.stderr, r.stderr


def test_sigterm_then_resume_bitwise_on_two_ranks(work):
    d = work["dir"]
    step, rank = RNG.randint(3, STEPS - 3), RNG.randint(0, 1)
    out = d / "term" / "out.h5"
    r = cli(d, "run", "scene.yaml", "--output", out, env={"DISTCLOTH_SIGNAL_AT": f"{rank}:{step}"})
    why = f"SIGTERM to rank {rank} after step {step} (seed {SEED})"
    assert r.returncode == 128 + signal.SIGTERM, (why, r.stderr)
    no_traceback(r)
    assert sum("interrupted by SIGTERM" in line for line in r.stderr.splitlines()) == 1, r.stderr
    attrs = read_attrs(out)
    assert (attrs["status"], attrs["interrupted_step"], attrs["interrupted_by"]) == \
        ("interrupted", step, "SIGTERM"), why
    assert attrs["steps_written"] == step, why       # the buffered diagnostics were written
    scalars, _, _ = read_checkpoint(checkpoint_path(str(out)))
    assert scalars["step"] == step, why
    # a copy for the resume on three ranks
    shutil.copytree(d / "term", d / "term3")

    r = cli(d, "run", "scene.yaml", "--resume", out)
    assert r.returncode == 0, (why, r.stderr)
    res = read_result(out)
    assert res["attrs"]["status"] == "completed"
    assert list(res["attrs"]["resumed_at"]) == [step]
    same_run(res, work["ref"])


def test_resume_on_three_ranks_within_tolerance(work):
    d = work["dir"]
    if not (d / "term3").exists():
        pytest.skip("needs the interrupted run of the test before")
    out = d / "term3" / "out.h5"
    # from the checkpoint itself: it names its result file
    r = cli(d, "run", "scene.yaml", "--resume", checkpoint_path(str(out)), ranks=3)
    assert r.returncode == 0, r.stderr
    res, ref = read_result(out), work["ref"]
    assert res["attrs"]["ranks"] == 3 and res["part"].max() == 2
    assert np.array_equal(res["step"], ref["step"])
    # CG to a relative residual of 1e-5 with another block-Jacobi split: the
    # positions (a 0.6 m sheet) agree to a small multiple of that
    assert np.max(np.abs(res["positions"] - ref["positions"])) < 1e-4


def test_sigkill_then_resume_from_last_checkpoint(work):
    d = work["dir"]
    every = 4
    step, rank = RNG.randint(every + 1, STEPS - 3), RNG.randint(0, 1)
    why = f"SIGKILL to rank {rank} after step {step} (seed {SEED})"
    out = d / "kill" / "out.h5"
    every_set = f"output.checkpoint.every_steps={every}"
    r = cli(d, "run", "scene.yaml", "--output", out, "--set", every_set,
            env={"DISTCLOTH_SIGNAL_AT": f"{rank}:{step}:KILL"})
    assert r.returncode != 0, why
    assert read_attrs(out)["status"] == "running", why
    last = (step - 1) // every * every       # killed before the checkpoint of its own step
    assert read_checkpoint(checkpoint_path(str(out)))[0]["step"] == last, why
    shown = cli(d, "inspect", out, ranks=None)
    assert shown.returncode == 0, shown.stderr
    assert "the run was killed" in shown.stdout, shown.stdout
    assert f"step {last}," in shown.stdout, shown.stdout

    r = cli(d, "run", "scene.yaml", "--resume", out, "--set", every_set)
    assert r.returncode == 0, (why, r.stderr)
    assert "the run was killed" in r.stderr
    res = read_result(out)
    assert list(res["attrs"]["resumed_at"]) == [last], why
    same_run(res, work["ref"])


def test_resume_refuses_another_scene_and_extends_time_end(work):
    d = work["dir"]
    out = d / "short" / "out.h5"
    r = cli(d, "run", "scene.yaml", "--output", out, "--set", "time.end=0.15")
    assert r.returncode == 0, r.stderr
    before = read_attrs(out)
    r = cli(d, "run", "scene.yaml", "--resume", out, "--set", "cloth.0.material.stretch=90")
    assert r.returncode == 2
    no_traceback(r)
    first = r.stderr.strip().splitlines()[0]
    assert "cloth.0.material.stretch" in first and "as in the checkpoint" in first, r.stderr
    assert read_attrs(out)["steps_written"] == before["steps_written"] == STEPS // 2

    r = cli(d, "run", "scene.yaml", "--resume", out)       # time.end back to 0.3 s
    assert r.returncode == 0, r.stderr
    same_run(read_result(out), work["ref"])


def test_resume_refuses_a_result_the_checkpoint_does_not_belong_to(work):
    """A result file replaced beside its checkpoint (here by another run's, of
    another resolution) is refused before anything in it changes: exit 2 and
    one line, the replaced file as it was."""
    d = work["dir"]
    out, other = d / "replaced" / "out.h5", d / "other" / "out.h5"
    r = cli(d, "run", "scene.yaml", "--output", out, "--set", "time.end=0.15")
    assert r.returncode == 0, r.stderr
    r = cli(d, "run", "scene.yaml", "--output", other, "--set", "time.end=0.1",
            "--set", "cloth.0.mesh.grid.resolution=[7,7]")
    assert r.returncode == 0, r.stderr
    shutil.copyfile(other, out)
    before = read_result(out)
    r = cli(d, "run", "scene.yaml", "--resume", checkpoint_path(str(out)))
    assert r.returncode == 2, r.stderr
    no_traceback(r)
    first = r.stderr.strip().splitlines()[0]     # then mpiexec's note of the exit status
    assert first.startswith("distcloth: config error: --resume:"), r.stderr
    assert "(it has 49 vertices, the resumed run 81)" in first, r.stderr
    assert r.stderr.count("config error") == 1, r.stderr
    after = read_result(out)
    assert after["attrs"]["steps_written"] == before["attrs"]["steps_written"]
    assert np.array_equal(after["positions"], before["positions"])
    assert after["attrs"]["status"] == "completed"


def test_sigint_to_mpiexec_stops_cleanly(work):
    """Ctrl-C at a terminal: mpiexec relays it to every rank as SIGTERM."""
    d = work["dir"]
    out = d / "sigint" / "out.h5"
    cmd = ["mpiexec", "--oversubscribe", "-n", "2", sys.executable, "-m", "distcloth", "run",
           "scene.yaml", "--output", str(out), "--set", "time.end=20", "--set",
           "output.checkpoint.every_steps=5", "--quiet"]
    # Open MPI's default: SIGKILL one second after the relayed SIGTERM (docs/restart.md)
    p = subprocess.Popen(cmd, env=clean_env(OMPI_MCA_odls_base_sigkill_timeout="1"), cwd=d,
                         stderr=subprocess.PIPE, text=True)
    ckpt = checkpoint_path(str(out))
    t0 = time.monotonic()
    while not os.path.exists(ckpt) and p.poll() is None and time.monotonic() - t0 < 60:
        time.sleep(0.05)
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=60)
    assert "Traceback" not in err, err
    attrs = read_attrs(out)
    assert attrs["status"] == "interrupted", err
    assert read_checkpoint(ckpt)[0]["step"] == attrs["interrupted_step"] == attrs["steps_written"]


def test_inspect(work, tmp_path):
    r = cli(tmp_path, "inspect", work["ref_path"], ranks=None)
    assert r.returncode == 0, r.stderr
    text = r.stdout
    for expected in ("scene:      tiny_sphere", "ranks:      2", "status:     completed",
                     f"steps:      {STEPS} written of {STEPS}", "frames:     7 written",
                     f"checkpoint: {checkpoint_path(str(work['ref_path']))}: step {STEPS}",
                     "stage time", "solve", "warnings:"):
        assert expected in text, text
    bad = tmp_path / "bad.h5"
    bad.write_text("not hdf5")
    r = cli(tmp_path, "inspect", bad, ranks=None)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr
