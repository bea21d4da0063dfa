"""Result file, XDMF sidecar, previews and read-back (distcloth.io).

Written for ``mpiexec -n 2 python -m pytest``: every writer test is collective
(all ranks write their own rows of one shared file, whose path rank 0 picks
and broadcasts) and rank 0 alone reads the file back with plain h5py and
checks it against the synthetic global arrays, which every rank generates
identically from a fixed seed.  Also passes on one rank.
"""
from __future__ import annotations

import os
import re
import subprocess
import sys
import textwrap
import time
import xml.etree.ElementTree as ET

import h5py
import numpy as np
import pytest
from mpi4py import MPI

from distcloth.io import (CollectiveError, ResultWriter, check_xdmf, read_colliders, read_result,
                          write_previews)
from distcloth.io import h5writer
from distcloth.parallel.comm import Comm
from conftest import clean_env as mpi_env

COMM = MPI.COMM_WORLD
RANK, SIZE = COMM.rank, COMM.size
REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

DIAGS = ["kinetic_energy", "gravitational_energy", "elastic_energy", "total_energy",
         "ksp_iterations", "newton_iterations"]
STAGES = ["forces", "assemble", "solve"]


# ---------------------------------------------------------------- helpers

@pytest.fixture
def shared_dir(tmp_path):
    """A directory every rank agrees on (rank 0's tmp_path)."""
    return COMM.bcast(str(tmp_path) if RANK == 0 else None, root=0)


def blocky_partition(n: int, size: int, seed: int = 3, max_block: int = 60) -> np.ndarray:
    """Runs of random length (1..max_block) given to random ranks: owned rows
    are scattered through the input order, as with METIS."""
    rng = np.random.default_rng(seed)
    lengths = rng.integers(1, max_block + 1, size=n)
    cuts = np.cumsum(lengths)
    cuts = cuts[cuts < n]
    block_rank = rng.integers(0, size, size=cuts.size + 1)
    block_rank[:size] = np.arange(size)     # every rank owns something
    return np.repeat(block_rank, np.diff(np.r_[0, cuts, n])).astype(np.int32)


class Synthetic:
    """A run everyone can regenerate: mesh, frames, steps, all from one seed."""

    def __init__(self, n=1000, frames=4, steps_per_frame=5, seed=11, part=None):
        rng = np.random.default_rng(seed)
        self.n = n
        self.rest = rng.random((n, 3))
        self.triangles = rng.integers(0, n, size=(2 * n - 3, 3)).astype(np.int64)
        self.part = blocky_partition(n, SIZE) if part is None else part
        self.frames = rng.standard_normal((frames, n, 3))
        self.frame_step = (np.arange(frames) + 1) * steps_per_frame - 1
        self.frame_time = 0.01 * (self.frame_step + 1)
        nsteps = frames * steps_per_frame
        self.step = np.arange(nsteps)
        self.time = 0.01 * (self.step + 1)
        self.diag = {k: rng.standard_normal(nsteps) for k in DIAGS}
        self.stage_time = {k: rng.random(nsteps) for k in STAGES}
        self.stage_calls = {k: rng.integers(0, 5, nsteps) for k in STAGES}
        self.steps_per_frame = steps_per_frame
        # this rank's vertices in a scrambled local order, like a LocalLayout
        mine = np.flatnonzero(self.part == RANK)
        self.owned = np.random.default_rng(100 + RANK).permutation(mine)
        self.config = "scene: test\ncloth: {name: tablecloth}\n# ünïcode\n"
        self.attrs = {"scene": "synthetic", "ranks": SIZE, "integrator": "backward_euler",
                      "ksp_rtol": 1e-8, "verbose": False, "resolution": [40, 25]}

    def writer(self, path, comm=COMM, diagnostic_names=DIAGS, **kw):
        return ResultWriter(path, Comm(comm), rest_positions=self.rest, triangles=self.triangles,
                            owned_input=self.owned, part=self.part, config_text=self.config,
                            attrs=self.attrs, stage_names=STAGES,
                            diagnostic_names=diagnostic_names, **kw)

    def write_steps(self, w, frame):
        for s in range(frame * self.steps_per_frame, (frame + 1) * self.steps_per_frame):
            w.write_step(int(self.step[s]), float(self.time[s]),
                         {k: v[s] for k, v in self.diag.items()},
                         {k: v[s] for k, v in self.stage_time.items()},
                         {k: int(v[s]) for k, v in self.stage_calls.items()})

    def write_frame(self, w, k):
        w.write_frame(int(self.frame_step[k]), float(self.frame_time[k]), self.frames[k][self.owned])

    def check_steps(self, r):
        """Every per-step table of ``read_result``'s ``r`` is this run's."""
        assert np.array_equal(r["diagnostics"]["step"], self.step)
        assert np.array_equal(r["diagnostics"]["time"], self.time)
        for k in DIAGS:
            assert np.array_equal(r["diagnostics"][k], self.diag[k]), k
        for k in STAGES:
            assert np.array_equal(r["stage_time"][k], self.stage_time[k]), k
            assert np.array_equal(r["stage_calls"][k], self.stage_calls[k]), k

    def write_run(self, w, frames=None):
        for k in range(self.frames.shape[0] if frames is None else frames):
            self.write_steps(w, k)
            self.write_frame(w, k)


def on_root(check):
    """Run ``check`` on rank 0, then share its outcome so every rank passes or fails."""
    err = None
    if RANK == 0:
        try:
            check()
        except BaseException as e:   # noqa: BLE001 - re-raised below on every rank
            err = e
    failed = COMM.bcast(None if err is None else repr(err), root=0)
    if err is not None:
        raise err
    if failed is not None:
        pytest.fail(f"rank 0 failed: {failed}")


def all_ranks(ok: bool, what: str) -> None:
    """Assert on every rank at once: a rank failing alone would leave the
    others waiting in the writer's next collective call."""
    if not COMM.allreduce(bool(ok), op=MPI.LAND):
        pytest.fail(f"{what} (failed on some rank; this rank: {'ok' if ok else 'failed'})")


def raises(exc_type, match, fn):
    """(raised as expected, result of fn if it did not raise), without
    leaving this rank before the others."""
    try:
        return False, fn()
    except exc_type as err:
        return re.search(match, str(err)) is not None, None


def clean_env() -> dict:
    """Environment for a serial child: no trace of the MPI launch."""
    env = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_"))}
    env["PYTHONPATH"] = REPO + os.pathsep + env.get("PYTHONPATH", "")
    env.pop("H5PY_ALWAYS_USE_MPI", None)
    return env


# ---------------------------------------------------------------- round trip

@pytest.mark.parametrize("step_buffer", [3, 1024])
def test_round_trip_in_input_order(shared_dir, step_buffer):
    syn = Synthetic()
    path = os.path.join(shared_dir, "sub", "run.h5")       # parent made by the writer
    with syn.writer(path, step_buffer=step_buffer) as w:
        syn.write_run(w)
    assert w.closed

    def check():
        r = read_result(path)
        assert r["frames_written"] == 4 and r["steps_written"] == 20
        assert r["positions"].shape == (4, syn.n, 3)
        assert np.array_equal(r["positions"], syn.frames)        # exactly, input order
        assert np.array_equal(r["time"], syn.frame_time)
        assert np.array_equal(r["step"], syn.frame_step)
        assert np.array_equal(r["rest_positions"], syn.rest)
        assert np.array_equal(r["triangles"], syn.triangles)
        assert np.array_equal(r["part"], syn.part)
        assert r["config"] == syn.config
        syn.check_steps(r)
        a = r["attrs"]
        assert a["status"] == "completed" and a["error"] == "" and a["error_step"] == -1
        assert a["scene"] == "synthetic" and a["ranks"] == SIZE and a["ksp_rtol"] == 1e-8
        assert list(a["resolution"]) == [40, 25] and a["verbose"] is False
        with h5py.File(path, "r") as f:
            pos = f["frames/positions"]
            assert pos.dtype == np.float64 and pos.maxshape == (None, syn.n, 3)
            assert pos.chunks == (1, syn.n, 3)
            assert f["frames/step"].dtype == np.int64
            assert f["partition/part"].dtype == np.int32
            assert f["mesh/triangles"].dtype == np.int64
            assert f["diagnostics/stage_calls/solve"].dtype == np.int64
            assert all(f[f"diagnostics/{k}"].maxshape == (None,) for k in DIAGS)

    on_root(check)


def test_step_tables_grow_ahead_and_are_cut_at_close(shared_dir, monkeypatch):
    # tables grown 4 rows ahead, steps flushed 3 at a time and at every frame:
    # eight growths, flushes that straddle them, 44 rows for 40 steps cut at close
    monkeypatch.setattr(h5writer, "STEP_TABLE_GROWTH", 4)
    syn = Synthetic(frames=5, steps_per_frame=8)
    path = os.path.join(shared_dir, "grown.h5")
    with syn.writer(path, step_buffer=3) as w:
        syn.write_run(w)

    def check():
        r = read_result(path)
        assert r["steps_written"] == 40
        syn.check_steps(r)
        with h5py.File(path, "r") as f:
            tables = []
            f["diagnostics"].visititems(lambda name, obj: tables.append(obj.shape)
                                        if isinstance(obj, h5py.Dataset) else None)
            # 2 + diagnostics + stage times and calls, all cut to the steps written
            assert tables == [(40,)] * (2 + len(DIAGS) + 2 * len(STAGES))

    on_root(check)


def test_missing_values_are_nan_and_unknown_names_raise(shared_dir):
    syn = Synthetic(frames=2)
    path = os.path.join(shared_dir, "partial.h5")
    w = syn.writer(path, step_buffer=2)
    full = {k: 1.0 for k in DIAGS}
    w.write_step(0, 0.1, full, {k: 0.5 for k in STAGES}, {k: 3 for k in STAGES})
    w.write_step(1, 0.2, full, {k: 0.5 for k in STAGES}, {k: 3 for k in STAGES})  # buffer full
    w.write_step(2, 0.3, {"kinetic_energy": 2.0}, {"solve": 0.25}, {"solve": 4})
    ok, _ = raises(KeyError, "unknown diagnostic", lambda: w.write_step(3, 0.4, {"not_declared": 1.0}))
    all_ranks(ok, "write_step accepted an undeclared diagnostic")
    w.write_frame(2, 0.3, syn.frames[0][syn.owned])
    w.write_step(3, 0.4, {"elastic_energy": 5.0})
    w.close()

    def check():
        r = read_result(path)
        d, st, sc = r["diagnostics"], r["stage_time"], r["stage_calls"]
        assert r["steps_written"] == 4
        assert np.array_equal(d["step"], [0, 1, 2, 3])
        assert np.array_equal(d["kinetic_energy"][:3], [1.0, 1.0, 2.0]) and np.isnan(d["kinetic_energy"][3])
        assert np.isnan(d["elastic_energy"][2]) and d["elastic_energy"][3] == 5.0
        assert np.array_equal(sc["forces"], [3, 3, 0, 0]) and np.array_equal(sc["solve"], [3, 3, 4, 0])
        assert np.isnan(st["forces"][2]) and st["solve"][2] == 0.25 and np.isnan(st["solve"][3])

    on_root(check)


@pytest.mark.skipif(SIZE < 2, reason="needs a rank that owns nothing")
def test_rank_owning_nothing_takes_part(shared_dir):
    syn = Synthetic(part=np.zeros(1000, np.int32))     # everything on rank 0
    path = os.path.join(shared_dir, "empty_rank.h5")
    w = syn.writer(path)
    syn.write_run(w)
    w.close()
    all_ranks(w.selection_kind == ("hyperslab" if RANK == 0 else "none"), "selection kind")
    on_root(lambda: np.testing.assert_array_equal(read_result(path)["positions"], syn.frames))


def test_point_and_hyperslab_selections_mix(shared_dir, monkeypatch):
    """Above MAX_HYPERSLAB_RUNS a rank selects its rows as points; here rank 0
    does and the others use hyperslabs, in the same collective writes."""
    monkeypatch.setattr(h5writer, "MAX_HYPERSLAB_RUNS", 0 if RANK == 0 else 10**6)
    syn = Synthetic()
    path = os.path.join(shared_dir, "points.h5")
    w = syn.writer(path)
    syn.write_run(w)
    w.close()
    all_ranks(w.selection_kind == ("points" if RANK == 0 else "hyperslab"), "selection kind")
    mine = np.sort(syn.owned)
    all_ranks(w.selection_runs == 1 + np.count_nonzero(np.diff(mine) != 1), "run count")
    on_root(lambda: np.testing.assert_array_equal(read_result(path)["positions"], syn.frames))


def test_owned_input_must_match_part(shared_dir):
    syn = Synthetic()
    syn.owned = syn.owned[1:]           # a row nobody writes
    ok, w = raises(ValueError, "disagrees with part", lambda: syn.writer(os.path.join(shared_dir, "bad.h5")))
    if w is not None:
        w.close()
    all_ranks(ok, "owned_input inconsistent with part accepted")


def test_reserved_attribute_rejected(shared_dir):
    syn = Synthetic()
    syn.attrs["status"] = "mine"
    ok, w = raises(ValueError, "reserved", lambda: syn.writer(os.path.join(shared_dir, "bad.h5")))
    if w is not None:
        w.close()
    all_ranks(ok, "reserved attribute accepted")


def test_existing_file_is_replaced(shared_dir):
    path = os.path.join(shared_dir, "again.h5")
    big = Synthetic(frames=4)
    w = big.writer(path)
    big.write_run(w)
    w.close()
    small = Synthetic(frames=1, seed=12)
    w = small.writer(path)
    small.write_run(w)
    w.close()
    on_root(lambda: np.testing.assert_array_equal(read_result(path)["positions"], small.frames))


# ---------------------------------------------------------------- failures

def test_record_error_keeps_frames_and_marks_failed(shared_dir):
    syn = Synthetic()
    path = os.path.join(shared_dir, "failed.h5")
    w = syn.writer(path)
    syn.write_run(w, frames=2)
    syn.write_steps(w, 2)               # steps after the last frame are kept too
    # the message must be agreed; rank 0's wins if a caller gets it wrong
    w.record_error(12, "KSP diverged at step 12" if RANK == 0 else "another text")
    w.close()                            # 'completed' cannot overwrite a recorded error

    def check():
        r = read_result(path)
        a = r["attrs"]
        assert a["status"] == "failed"
        assert a["error"] == "KSP diverged at step 12" and a["error_step"] == 12
        assert r["frames_written"] == 2 and r["steps_written"] == 15
        assert np.array_equal(r["positions"], syn.frames[:2])
        assert check_xdmf(w.xdmf_path) == []
        assert len(ET.parse(w.xdmf_path).getroot().findall(".//Grid[@GridType='Uniform']")) == 2

    on_root(check)


def test_a_warning_makes_a_completed_run_completed_with_warnings(shared_dir):
    """Warnings are kept one per kind, with their step; a resumed file keeps
    those of the steps up to the resume step (a later one is met again)."""
    syn = Synthetic()
    path = os.path.join(shared_dir, "warned.h5")
    w = syn.writer(path)
    syn.write_run(w, frames=2)
    w.record_warning(7, "energy_gain", "step 7 (t = 0.08 s): energy gain" if RANK == 0 else "x")
    w.record_warning(9, "energy_gain", "a second one of the kind")           # kept: the first
    w.record_warning(9, "other", "step 9: another kind")
    assert w.close() == "completed_with_warnings"

    def check():
        a = read_result(path)["attrs"]
        assert a["status"] == "completed_with_warnings"
        assert a["warnings"] == ["step 7 (t = 0.08 s): energy gain", "step 9: another kind"]
        assert list(a["warning_steps"]) == [7, 9] and a["warning_kinds"] == ["energy_gain", "other"]

    on_root(check)
    w = syn.writer(path, resume_step=8)
    assert [k for _, k, _ in w.warnings()] == ["energy_gain"]
    assert w.close() == "completed_with_warnings"
    w = syn.writer(path, resume_step=4)
    assert w.warnings() == []
    assert w.close() == "completed"


def test_a_refused_resume_leaves_the_file_as_it_was(shared_dir, monkeypatch):
    """A result the resumed run cannot go on in is refused on every rank alike,
    with the file's frames and rows untouched: the checks run before any cut
    and are agreed, so a rank that finds a problem the others do not (here
    made to, on the last rank) stops them all instead of leaving them cutting."""
    syn = Synthetic()
    path = os.path.join(shared_dir, "refused.h5")
    w = syn.writer(path)
    syn.write_run(w, frames=2)
    w.close()

    def unchanged():
        r = read_result(path)
        assert r["attrs"]["status"] == "completed" and r["positions"].shape[0] == 2
        assert np.array_equal(r["diagnostics"]["step"], syn.step[:10])
        assert np.array_equal(r["diagnostics"]["kinetic_energy"], syn.diag["kinetic_energy"][:10])
        assert np.array_equal(r["positions"][1], syn.frames[1])

    with pytest.raises(h5writer.ResumeRefused, match="does not belong to this checkpoint"):
        syn.writer(path, resume_step=15)          # its rows end at step 9
    on_root(unchanged)
    other = Synthetic(n=900)
    with pytest.raises(h5writer.ResumeRefused, match="has 1000 vertices, the resumed run 900"):
        other.writer(path, resume_step=4)
    on_root(unchanged)
    with pytest.raises(h5writer.ResumeRefused, match=r"has no diagnostics \['strain'\]"):
        syn.writer(path, diagnostic_names=DIAGS + ["strain"], resume_step=4)
    on_root(unchanged)
    if RANK == SIZE - 1:
        monkeypatch.setattr(h5writer, "_resume_problem",
                            lambda *a, **k: ("cannot be read (made to fail here)", 0, 0))
    with pytest.raises(h5writer.ResumeRefused,
                       match=r"refused\.h5 cannot be read \(made to fail here\)"):
        syn.writer(path, resume_step=4)
    on_root(unchanged)


THREE_RANK_RESUME = textwrap.dedent("""
    import sys
    import numpy as np
    from mpi4py import MPI
    sys.path.insert(0, %r)
    from test_io import Synthetic
    comm = MPI.COMM_WORLD
    path = sys.argv[1]
    for trial in range(4):          # the same path again: a file replaced, then resumed
        syn = Synthetic()
        w = syn.writer(path)
        syn.write_run(w, frames=2)
        w.close()
        for step in (8, 4):
            w = syn.writer(path, resume_step=step)
            w.close()
            if comm.rank == 0:
                from distcloth.io import read_result
                r = read_result(path)
                assert np.array_equal(r["diagnostics"]["step"], np.arange(step + 1)), (trial, step)
                assert np.array_equal(r["diagnostics"]["kinetic_energy"],
                                      syn.diag["kinetic_energy"][:step + 1]), (trial, step)
            comm.Barrier()
""") % os.path.dirname(os.path.abspath(__file__))


@pytest.mark.skipif(RANK != 0, reason="launches its own three ranks from rank 0")
def test_resumed_file_reads_alike_on_three_ranks(tmp_path):
    # a rank that cut the tables while another still read them made that one
    # read the diagnostics of a resumed file as zeros past the first flush's
    # rows (every run of this child failed so, before the writer waited)
    proc = subprocess.run(["mpiexec", "--oversubscribe", "-n", "3", sys.executable, "-c",
                           THREE_RANK_RESUME, str(tmp_path / "resumed.h5")],
                          env=mpi_env(), capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr[-3000:]


def test_collective_error_in_with_block_closes_failed(shared_dir):
    syn = Synthetic()
    path = os.path.join(shared_dir, "collective.h5")
    with pytest.raises(CollectiveError):
        with syn.writer(path) as w:
            syn.write_run(w, frames=1)
            raise CollectiveError("cloth left the domain", step=4)   # on every rank
    assert w.closed

    def check():
        a = read_result(path)["attrs"]
        assert a["status"] == "failed" and a["error_step"] == 4
        assert "cloth left the domain" in a["error"]

    on_root(check)


def test_local_exception_makes_no_collective_call(shared_dir):
    """An ordinary exception may have been raised on some ranks only, so under
    MPI __exit__ must not close (a collective); the caller agrees and closes."""
    syn = Synthetic()
    path = os.path.join(shared_dir, "local.h5")
    with pytest.raises(ZeroDivisionError):
        with syn.writer(path) as w:
            syn.write_run(w, frames=1)
            1 / 0
    if SIZE == 1:
        assert w.closed                  # serial: nothing to deadlock, recorded and closed
    else:
        assert not w.closed
        w.record_error(-1, "agreed afterwards")
        w.close()

    def check():
        a = read_result(path)["attrs"]
        assert a["status"] == "failed" and a["frames_written"] == 1

    on_root(check)


# ---------------------------------------------------------------- XDMF

def test_xdmf_rewritten_each_frame_and_valid(shared_dir):
    syn = Synthetic()
    path = os.path.join(shared_dir, "xd.h5")
    w = syn.writer(path)
    seen = []       # (grids, last time) in the sidecar after each frame, checked after close
    for k in range(3):
        syn.write_steps(w, k)
        syn.write_frame(w, k)
        if RANK == 0:
            try:
                grids = ET.parse(w.xdmf_path).getroot().findall(".//Grid[@GridType='Uniform']")
                seen.append((len(grids), float(grids[-1].find("Time").get("Value"))))
            except Exception as err:   # noqa: BLE001 - reported after close
                seen.append(repr(err))
    w.close()

    def check():
        assert seen == [(k + 1, syn.frame_time[k]) for k in range(3)]
        assert w.xdmf_path == os.path.join(shared_dir, "xd.xdmf")
        assert check_xdmf(w.xdmf_path) == []
        text = open(w.xdmf_path).read()
        assert "xd.h5:/xdmf/frames/positions/000002" in text and shared_dir not in text   # relative
        root = ET.parse(w.xdmf_path).getroot()
        coll = root.findall("Domain/Grid")[-1]      # the cloth's comes last (meshio reads the last)
        assert coll.get("Name") == "cloth"
        assert coll.get("GridType") == "Collection" and coll.get("CollectionType") == "Temporal"
        assert not root.findall(".//DataItem[@ItemType='HyperSlab']")
        with h5py.File(path, "r") as f:
            view = f["xdmf/frames/positions/000002"]
            assert view.is_virtual and view.shape == (syn.n, 3)
            assert np.array_equal(view[...], f["frames/positions"][2])
        assert not [p for p in os.listdir(shared_dir) if p.endswith(".tmp")]

    on_root(check)


def test_a_long_series_sidecar_is_rewritten_when_due_and_whole_at_close(shared_dir,
                                                                         monkeypatch):
    """Past XDMF_EVERY_FRAME_BELOW frames the sidecar is rewritten after a
    frame only once XDMF_TIME_RATIO times its last rewrite's time has passed:
    a rewrite made to take 20 ms allows the next 0.4 s later, so of 16 frames
    written back to back (a few ms each) at most a few rewrite it; closing the
    file lists every frame."""
    from distcloth.io import h5writer
    from distcloth.io.xdmf import XdmfSeries
    below = h5writer.XDMF_EVERY_FRAME_BELOW
    rewrites = []
    plain = XdmfSeries.write

    def slow(series, path):
        plain(series, path)
        time.sleep(0.02)
        rewrites.append(len(series))

    monkeypatch.setattr(XdmfSeries, "write", slow)
    syn = Synthetic(n=60, frames=below + 16, steps_per_frame=1)
    path = os.path.join(shared_dir, "long.h5")
    w = syn.writer(path)
    syn.write_run(w)
    after_frames = list(rewrites)
    w.close()

    def check():
        # every frame up to the limit, then few: without the rule all 16
        assert after_frames[:below] == list(range(1, below + 1)), after_frames
        assert len(after_frames) - below <= 4, after_frames
        assert rewrites[-1] == below + 16
        assert len(ET.parse(w.xdmf_path).getroot().findall(
            ".//Grid[@GridType='Uniform']")) == below + 16
        assert check_xdmf(w.xdmf_path) == []

    on_root(check)


def test_frame_fields_in_input_order_with_views(shared_dir):
    """Per-vertex and per-triangle fields: each rank writes its rows (vertices
    in its scrambled local order, triangles whose first vertex it owns) and
    the file holds them in input order, with a view per frame for XDMF."""
    syn = Synthetic(frames=3)
    rng = np.random.default_rng(5)
    nt = syn.triangles.shape[0]
    vel = rng.standard_normal((3, syn.n, 3))
    contact = rng.integers(0, 2, (3, syn.n)).astype(np.int8)
    strain = rng.standard_normal((3, nt))
    fields = [h5writer.FrameField("velocity", "vertex", 3), h5writer.FrameField("contact", dtype="i1"),
              h5writer.FrameField("strain", "triangle")]
    path = os.path.join(shared_dir, "fields.h5")
    w = syn.writer(path, fields=fields)
    mine_t = h5writer.triangle_rows(syn.triangles, syn.part, RANK)
    assert np.array_equal(w.owned_triangles, mine_t)
    for k in range(3):
        syn.write_steps(w, k)
        w.write_frame(int(syn.frame_step[k]), float(syn.frame_time[k]), syn.frames[k][syn.owned],
                      fields={"velocity": vel[k][syn.owned], "contact": contact[k][syn.owned],
                              "strain": strain[k][mine_t]})
    all_ranks(raises(ValueError, "strain", lambda: w.write_frame(
        9, 9.0, syn.frames[0][syn.owned], fields={"velocity": vel[0][syn.owned],
                                                  "contact": contact[0][syn.owned]}))[0],
              "a missing field is refused")
    w.close()

    def check():
        with h5py.File(path, "r") as f:
            assert np.array_equal(f["frames/velocity"][...], vel)
            assert np.array_equal(f["frames/contact"][...], contact)
            assert f["frames/contact"].dtype == np.int8
            assert np.array_equal(f["frames/strain"][...], strain)
            for k in range(3):
                assert np.array_equal(f[f"xdmf/frames/strain/{k:06d}"][...], strain[k])
                assert np.array_equal(f[f"xdmf/frames/velocity/{k:06d}"][...], vel[k])
        assert check_xdmf(w.xdmf_path) == []
        grid = ET.parse(w.xdmf_path).getroot().findall(".//Grid[@GridType='Uniform']")[-1]
        centers = {a.get("Name"): a.get("Center") for a in grid.findall("Attribute")}
        assert centers == {"position": "Node", "rank": "Node", "velocity": "Node",
                           "contact": "Node", "strain": "Cell"}

    on_root(check)


def test_check_xdmf_catches_corruption(shared_dir):
    syn = Synthetic()
    path = os.path.join(shared_dir, "bad_xdmf.h5")
    w = syn.writer(path)
    syn.write_run(w, frames=2)
    w.close()

    def check():
        good = open(w.xdmf_path).read()
        assert check_xdmf(w.xdmf_path) == []
        n, nt = syn.n, syn.triangles.shape[0]
        cases = {
            "wrong source dims": good.replace(f'Dimensions="{n} 3"', f'Dimensions="{n - 1} 3"'),
            "wrong topology dims": good.replace(f'Dimensions="{nt} 3"', f'Dimensions="{nt + 1} 3"'),
            "frame past the end": good.replace("positions/000001", "positions/000002"),
            "a hyperslab": good.replace(
                f'<DataItem Dimensions="{n} 3" NumberType="Float" Precision="8" Format="HDF">'
                'bad_xdmf.h5:/xdmf/frames/positions/000001</DataItem>',
                f'<DataItem ItemType="HyperSlab" Dimensions="{n} 3" Type="HyperSlab">'
                f'<DataItem Dimensions="3 3" Format="XML">1 0 0 1 1 1 1 {n} 3</DataItem>'
                f'<DataItem Dimensions="2 {n} 3" NumberType="Float" Precision="8" Format="HDF">'
                'bad_xdmf.h5:/frames/positions</DataItem></DataItem>'),
            "missing dataset": good.replace("/mesh/triangles", "/mesh/quads"),
            "wrong precision": good.replace('NumberType="Int" Precision="4"',
                                            'NumberType="Int" Precision="8"'),
        }
        for what, text in cases.items():
            assert text != good, what
            bad = os.path.join(shared_dir, "corrupt.xdmf")
            with open(bad, "w") as fh:
                fh.write(text)
            assert check_xdmf(bad), f"check_xdmf missed: {what}"
        assert any("Dimensions" in p for p in check_xdmf_text(shared_dir, cases["wrong source dims"]))
        assert any("HyperSlab" in p for p in check_xdmf_text(shared_dir, cases["a hyperslab"]))
        # a view mapping rows its source no longer has would read as zeros
        with h5py.File(path, "a") as f:
            f["frames/positions"].resize(1, axis=0)
        assert any("beyond" in p for p in check_xdmf(w.xdmf_path))

    on_root(check)


def check_xdmf_text(folder, text):
    path = os.path.join(folder, "corrupt.xdmf")
    with open(path, "w") as fh:
        fh.write(text)
    return check_xdmf(path)


# ---------------------------------------------------------------- serial

SERIAL_SCRIPT = textwrap.dedent("""
    import os, sys
    import h5py, numpy as np
    from distcloth.io import ResultWriter
    assert not h5py.get_config().mpi, "the serial child loaded h5py's MPI build"
    path, mode, seed = sys.argv[1], sys.argv[2], int(sys.argv[3])
    rng = np.random.default_rng(seed)
    n = 1000
    rest = rng.random((n, 3))
    triangles = rng.integers(0, n, size=(2 * n - 3, 3))
    frames = rng.standard_normal((4, n, 3))
    w = ResultWriter(path, None, rest_positions=rest, triangles=triangles,
                     owned_input=np.arange(n), part=np.zeros(n, np.int32),
                     config_text="serial", attrs={"scene": "serial"},
                     stage_names=%r, diagnostic_names=%r)
    for k in range(4):
        for s in range(5):
            w.write_step(5 * k + s, 0.1 * k, {"kinetic_energy": float(k)}, {"solve": 0.1}, {"solve": 1})
        w.write_frame(k, 0.1 * k, frames[k])
        if mode == "crash" and k == 1:
            os._exit(3)          # no close: what a killed run leaves behind
        if mode == "error" and k == 1:
            w.record_error(7, "diverged")
            os._exit(4)          # killed after recording the error, before close
    w.close()
    np.save(path + ".frames.npy", frames)
""") % (STAGES, DIAGS)


def layout(path):
    """{dataset path: (shape, dtype)} and the root attribute names of a file
    (the config string's length is the text's, so only its kind is kept)."""
    out = {}

    def visit(name, obj):
        if isinstance(obj, h5py.Dataset):
            out[name] = (obj.shape, obj.dtype.kind if name == "config" else obj.dtype)

    with h5py.File(path, "r") as f:
        f.visititems(visit)
        return out, set(f.attrs)


def run_serial(args):
    return subprocess.run([sys.executable, "-c", SERIAL_SCRIPT, *args], env=clean_env(),
                          capture_output=True, text=True, timeout=120)


@pytest.mark.skipif(RANK != 0, reason="a serial child is launched from rank 0 only")
def test_serial_writer_same_layout(tmp_path):
    # the parallel file, written by this rank alone through a size-1 split of
    # the world (so the other ranks need not join), then the serial child's
    syn = Synthetic(part=np.zeros(1000, np.int32))
    syn.owned = np.arange(1000)
    self_comm = MPI.COMM_SELF
    par = str(tmp_path / "par.h5")
    w = syn.writer(par, comm=self_comm)
    syn.write_run(w)
    w.close()
    ser = str(tmp_path / "ser.h5")
    proc = run_serial([ser, "normal", "5"])
    assert proc.returncode == 0, proc.stderr
    par_layout, par_attrs = layout(par)
    ser_layout, ser_attrs = layout(ser)
    assert par_layout == ser_layout
    assert par_attrs - set(syn.attrs) == ser_attrs - {"scene"}
    r = read_result(ser)
    assert np.array_equal(r["positions"], np.load(ser + ".frames.npy"))
    assert r["attrs"]["status"] == "completed"
    assert check_xdmf(str(tmp_path / "ser.xdmf")) == []


@pytest.mark.skipif(RANK != 0, reason="a serial child is launched from rank 0 only")
def test_killed_run_leaves_frames_readable(tmp_path):
    path = str(tmp_path / "crash.h5")
    proc = run_serial([path, "crash", "5"])
    assert proc.returncode == 3, proc.stderr
    r = read_result(path)
    assert r["attrs"]["status"] == "running"       # never closed
    assert r["frames_written"] == 2 and r["steps_written"] == 10
    # the tables had grown ahead of the steps written; the reader cuts them
    with h5py.File(path, "r") as f:
        assert f["diagnostics/kinetic_energy"].shape[0] > 10
    assert np.array_equal(r["diagnostics"]["kinetic_energy"], np.repeat([0.0, 1.0], 5))
    assert np.array_equal(r["diagnostics"]["step"], np.arange(10))
    frames = np.random.default_rng(5)
    frames.random((1000, 3))
    frames.integers(0, 1000, size=(1997, 3))
    assert np.array_equal(r["positions"], frames.standard_normal((4, 1000, 3))[:2])
    assert check_xdmf(str(tmp_path / "crash.xdmf")) == []
    proc = run_serial([path, "error", "5"])
    assert proc.returncode == 4, proc.stderr
    r = read_result(path, positions=False)
    assert (r["attrs"]["status"], r["attrs"]["error"], r["attrs"]["error_step"]) == ("failed", "diverged", 7)
    assert r["frames_written"] == 2


# ---------------------------------------------------------------- previews

def test_previews_written(shared_dir):
    syn = Synthetic()
    path = os.path.join(shared_dir, "prev.h5")
    with syn.writer(path) as w:
        syn.write_run(w)
    failed = os.path.join(shared_dir, "prev_failed.h5")
    w = syn.writer(failed)
    syn.write_run(w, frames=1)
    w.record_error(5, "stopped")
    w.close()

    def check():
        for p in (path, failed):
            out = write_previews(p)
            stem = os.path.splitext(p)[0]
            assert sorted(out) == sorted([stem + "_energy.png", stem + "_frames.png"])
            for png in out:
                with open(png, "rb") as fh:
                    head = fh.read(8)
                assert head == b"\x89PNG\r\n\x1a\n" and os.path.getsize(png) > 10_000

    on_root(check)


def test_preview_decimation_keeps_a_surface():
    from distcloth.io.preview import decimate, pick_frames
    nu = 200
    i, j = np.meshgrid(np.arange(nu), np.arange(nu))
    rest = np.c_[i.ravel(), j.ravel(), np.zeros(nu * nu)] / (nu - 1)
    idx = np.arange(nu * nu).reshape(nu, nu)
    a, b, c, d = (x.ravel() for x in (idx[:-1, :-1], idx[:-1, 1:], idx[1:, :-1], idx[1:, 1:]))
    tri = np.concatenate([np.c_[a, b, d], np.c_[a, d, c]])
    cluster, coarse = decimate(rest, tri, 5000)
    assert 2500 < coarse.shape[0] <= 5000
    # no holes: the coarse triangles still cover the unit square
    centers = np.stack([np.bincount(cluster, weights=rest[:, k]) / np.bincount(cluster)
                        for k in range(2)], axis=1)
    p = centers[coarse]
    area = 0.5 * np.abs(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])).sum()
    assert area > 0.9
    assert pick_frames(1) == [0] and pick_frames(10) == [0, 3, 6, 9] and pick_frames(0) == []


# ---------------------------------------------------------------- colliders

class FakeBody:
    """A collider surface as the writer takes it (collision/surfaces.py makes
    the real ones): a fixed triangle, moved along ``velocity`` if given."""

    def __init__(self, name, velocity=None):
        self.name, self.shape = name, "mesh"
        self.triangles = np.array([[0, 1, 2]], dtype=np.int64)
        self.rest = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
        self.velocity = velocity
        self.moving = velocity is not None

    def vertices(self, t):
        return self.rest if self.velocity is None else self.rest + t * np.asarray(self.velocity)


def scene_colliders():
    """A sphere sliding 1 m/s along x and a static floor, as run.py builds them
    (the same on every rank), and a body whose name is not a group name."""
    from distcloth.collision.colliders import AnalyticCollider, Plane, RigidMotion, Sphere
    from distcloth.collision.contact import Collider
    from distcloth.collision.surfaces import collider_surfaces

    def collider(name, shape, motion=None):
        return Collider(name=name, kind="analytic", query=None, friction=0.0, thickness=0.0,
                        law="", body=AnalyticCollider(shape, motion))

    slide = RigidMotion([0.0, 1.0], [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    colliders = [collider("ball", Sphere((0.0, 0.0, 0.25), 0.25), slide),
                 collider("floor", Plane((0.0, 0.0, 1.0), 0.0))]
    rest = np.array([[-0.5, -0.5, 0.6], [0.5, 0.5, 0.6]])
    return colliders, collider_surfaces(colliders, rest) + [FakeBody("arm/left")]


def test_colliders_are_written_read_and_drawn(shared_dir):
    from distcloth.collision.surfaces import collider_surface
    syn = Synthetic(frames=3)
    colliders, surfaces = scene_colliders()
    path = os.path.join(shared_dir, "bodies.h5")
    with syn.writer(path, colliders=surfaces) as w:
        syn.write_run(w)
    bare = os.path.join(shared_dir, "bare.h5")
    with syn.writer(bare) as w:
        syn.write_run(w, frames=1)

    def check():
        with h5py.File(path, "r") as f:
            assert f.attrs["format_version"] == 3
            assert sorted(f["colliders"]) == ["arm_left", "ball", "floor"]
            ball, floor = f["colliders/ball"], f["colliders/floor"]
            assert (ball.attrs["shape"], bool(ball.attrs["moving"])) == ("sphere", True)
            assert (floor.attrs["shape"], bool(floor.attrs["moving"])) == ("plane", False)
            assert f["colliders/arm_left"].attrs["name"] == "arm/left"
            assert ball["positions"].shape == (3, ball["positions"].shape[1], 3)
            assert floor["positions"].shape == (1, 4, 3) and floor["triangles"].dtype == np.int64
            # the sphere where it was at each frame's time
            for k in (0, 2):
                x, tri = collider_surface(colliders[0], syn.frame_time[k], np.zeros((2, 3)))
                assert np.array_equal(ball["positions"][k], x)
                assert np.array_equal(ball["triangles"][...], tri)
            moved = ball["positions"][2].mean(axis=0) - ball["positions"][0].mean(axis=0)
            np.testing.assert_allclose(moved, [syn.frame_time[2] - syn.frame_time[0], 0, 0],
                                       atol=1e-12)
            # the floor's square: on the plane, centred under the cloth, twice its size
            square = floor["positions"][0]
            np.testing.assert_allclose([square.min(axis=0), square.max(axis=0)],
                                       [[-1, -1, 0], [1, 1, 0]], atol=1e-12)
        r = read_result(path, frames=[0, 2])
        assert sorted(r["colliders"]) == ["arm/left", "ball", "floor"]
        ball = r["colliders"]["ball"]
        assert ball["moving"] and ball["shape"] == "sphere" and ball["positions"].shape[0] == 2
        assert r["colliders"]["floor"]["positions"].shape == (1, 4, 3)
        one = read_colliders(path, frames=[1])["ball"]["positions"]
        np.testing.assert_array_equal(one[0], collider_surface(colliders[0], syn.frame_time[1],
                                                               np.zeros((2, 3)))[0])
        # ParaView: one temporal collection per collider, then the cloth's (meshio reads the last)
        sidecar = os.path.splitext(path)[0] + ".xdmf"
        assert check_xdmf(sidecar) == []
        series = ET.parse(sidecar).getroot().findall("Domain/Grid")
        assert [g.get("Name") for g in series] == ["collider ball", "collider floor",
                                                   "collider arm/left", "cloth"]
        assert all(len(g.findall("Grid")) == 3 for g in series)
        # a scene without colliders has no /colliders group
        with h5py.File(bare, "r") as f:
            assert "colliders" not in f
        assert check_xdmf(os.path.splitext(bare)[0] + ".xdmf") == []
        assert read_result(bare)["colliders"] == {}
        out = write_previews(path)
        frames_png = [p for p in out if p.endswith("_frames.png")][0]
        with open(frames_png, "rb") as fh:
            assert fh.read(8) == b"\x89PNG\r\n\x1a\n"
        assert os.path.getsize(frames_png) > 10_000

    on_root(check)



def test_views_of_a_body(shared_dir, monkeypatch):
    """A file with a mesh collider (a body) gets ``_views.png``: the last frame
    from the front and from the side, the body whole even two cloth sizes
    above the cloth; analytic colliders alone get none."""
    from distcloth.io import preview
    syn = Synthetic(frames=3)
    colliders, surfaces = scene_colliders()
    last = syn.frames[-1]
    top = last[:, 2].max() + 2.0 * float((last.max(axis=0) - last.min(axis=0)).max())
    body = surfaces[-1]                                       # the mesh one
    body.rest = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, top]])
    dressed, bare = (os.path.join(shared_dir, f"{s}.h5") for s in ("dressed", "bare"))
    with syn.writer(dressed, colliders=surfaces) as w:
        syn.write_run(w)
    with syn.writer(bare, colliders=surfaces[:2]) as w:       # a sphere and a floor
        syn.write_run(w)
    figures = {}

    class Recording(preview.Figure):
        def savefig(self, out, *args, **kwargs):
            figures[os.path.basename(out)] = self
            super().savefig(out, *args, **kwargs)

    monkeypatch.setattr(preview, "Figure", Recording)

    def check():
        out = write_previews(dressed)
        assert sorted(os.path.basename(p) for p in out) == [
            "dressed_energy.png", "dressed_frames.png", "dressed_views.png"]
        with open(os.path.join(shared_dir, "dressed_views.png"), "rb") as fh:
            assert fh.read(8) == b"\x89PNG\r\n\x1a\n"
        axes = figures["dressed_views.png"].axes
        assert [(ax.get_title(), ax.azim) for ax in axes] == [("front", -90), ("side", 0)]
        assert all(ax.get_zlim()[1] >= top - 1e-9 for ax in axes)
        assert f"t = {syn.frame_time[-1]:.4g} s" in figures["dressed_views.png"]._suptitle.get_text()
        out = write_previews(bare)
        assert sorted(os.path.basename(p) for p in out) == ["bare_energy.png", "bare_frames.png"]

    on_root(check)

def test_preview_draws_the_colliders(tmp_path):
    """The frame picture with a collider differs from the one without, and a
    huge collider mesh is decimated to the budget."""
    from distcloth.io.preview import _bodies, _frames_png
    nu = 60
    i, j = np.meshgrid(np.arange(nu), np.arange(nu))
    grid = np.c_[i.ravel(), j.ravel(), np.zeros(nu * nu)] / (nu - 1)
    idx = np.arange(nu * nu).reshape(nu, nu)
    a, b, c, d = (x.ravel() for x in (idx[:-1, :-1], idx[:-1, 1:], idx[1:, :-1], idx[1:, 1:]))
    tri = np.concatenate([np.c_[a, b, d], np.c_[a, d, c]])
    res = {"positions": (grid + [0, 0, 1.0])[None], "time": np.zeros(1), "triangles": tri[:50],
           "rest_positions": grid, "attrs": {"scene": "t"}, "frames_written": 1}
    big = {"triangles": tri, "positions": grid[None], "moving": False, "shape": "mesh"}
    bodies, decimated = _bodies({"big": big}, 1000)
    assert decimated == 1 and bodies[0]["triangles"].shape[0] <= 1000
    without, with_body = str(tmp_path / "without.png"), str(tmp_path / "with.png")
    _frames_png(res, [0], without, 30000)
    _frames_png({**res, "colliders": {"big": big}}, [0], with_body, 30000)
    assert open(without, "rb").read() != open(with_body, "rb").read()
