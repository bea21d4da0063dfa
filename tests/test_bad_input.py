"""Every bad input ends as one config-error line naming the key path or the
argument, exit status 2, no traceback and no output file, under ``check`` and
under ``run`` alike, launched as a user does (scripts/mpiexec.sh 2).

The cases are run as two child jobs per case (check, run) on a tiny scene
(100 vertices, one step); rank 0 of the test job launches them.  A write
that fails during the run (a disk filling up) is tested in process on every
rank of the test job."""
from __future__ import annotations

import struct
import subprocess
import sys

import pytest
import yaml

from conftest import ROOT, clean_env

TINY = {
    "scene": "tiny",
    "cloth": [{"name": "sheet",
               "mesh": {"grid": {"size": [0.2, 0.2], "resolution": [10, 10]},
                        "center": [0.0, 0.0, 0.5]},
               "pins": [{"corner": "top_left"}],
               "material": {"model": "mass_spring", "density": 0.15, "stretch": 200.0,
                            "shear": 20.0, "bending": 2.0e-5}}],
    "effects": ["gravity", "membrane"],
    "time": {"end": 0.01, "step": 0.01},
    "output": {"file": "out/tiny.h5", "every": 0.01, "preview": False},
}
TRIANGLE_OBJ = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"
QUAD_OBJ = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3\nf 1 3 4\n"


def binary_ply(count: int, count_type: str = "int", fmt: str = "<i") -> bytes:
    """One triangle whose face-list length field says ``count``."""
    header = ("ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n"
              "property float y\nproperty float z\nelement face 1\n"
              f"property list {count_type} int vertex_indices\nend_header\n").encode()
    return (header + struct.pack("<9f", 0, 0, 0, 1, 0, 0, 0, 1, 0) + struct.pack(fmt, count)
            + struct.pack("<3i", 0, 1, 2))


def collider(files) -> dict:
    return {"effects": ["gravity", "membrane", "collisions"],
            "colliders": [{"name": "body", "shape": "mesh", "file": files}]}


# name -> (files to write, scene changes, extra arguments, text the error line must hold)
CASES = {
    "collider garbage": ({"c.obj": "garbage\n"}, collider("c.obj"), [], "colliders.0.file"),
    "collider NaN": ({"c.obj": "v 0 0 nan\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"}, collider("c.obj"), [],
                     "colliders.0.file"),
    "collider index out of range": ({"c.obj": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n"},
                                    collider("c.obj"), [], "colliders.0.file"),
    "collider truncated PLY": ({"c.ply": binary_ply(3)[:-5]}, collider("c.ply"), [],
                               "colliders.0.file"),
    "collider sequence frames differ": ({"a.obj": TRIANGLE_OBJ, "b.obj": QUAD_OBJ},
                                        {**collider(["a.obj", "b.obj"]),
                                         "colliders": [{"name": "body", "shape": "mesh",
                                                        "file": ["a.obj", "b.obj"],
                                                        "frame_rate": 10}]},
                                        [], "colliders.0.file.1"),
    "collider mesh without the collisions effect": ({"c.obj": "garbage\n"},
                                                    {"colliders": collider("c.obj")["colliders"]},
                                                    [], "colliders.0.file"),
    "PLY negative face-list count": ({"c.ply": binary_ply(-1, "char", "<b")}, collider("c.ply"),
                                     [], "colliders.0.file"),
    "PLY huge face-list count": ({"c.ply": binary_ply(2**31 - 1)}, collider("c.ply"), [],
                                 "colliders.0.file"),
    "cloth PLY negative face-list count": (
        {"c.ply": binary_ply(-3, "int", "<i")},
        {"cloth": [{**TINY["cloth"][0], "mesh": {"file": "c.ply"}, "pins": []}]}, [],
        "cloth.0.mesh.file"),
    "output is a directory": ({}, {}, ["--output", "{tmp}/dir.h5"], "--output"),
    "output under /proc": ({}, {}, ["--output", "/proc/distcloth/r.h5"], "--output"),
    "output under a file": ({"f.txt": "x"}, {}, ["--output", "{tmp}/f.txt/r.h5"], "--output"),
    "output exists": ({"out/tiny.h5": "previous"}, {}, [], "output.file"),
    "more ranks than vertices": ({"t.obj": TRIANGLE_OBJ}, {"cloth": [{
        **TINY["cloth"][0], "mesh": {"file": "t.obj"}, "pins": []}]}, [], "mpiexec -n"),
    "unreadable -options_file": ({}, {}, ["-options_file", "{tmp}/none.txt"],
                                 "-options_file"),
    "malformed PETSc option": ({}, {}, ["-distcloth_ksp_rtol=1e-8"], "-distcloth_ksp_rtol=1e-8"),
    "PETSc option without a value": ({}, {}, ["-distcloth_ksp_type"], "-distcloth_ksp_type"),
    "grid too large for memory": ({}, {"cloth": [{**TINY["cloth"][0], "mesh": {
        "grid": {"size": [0.2, 0.2], "resolution": [1000000, 1000000]}}}]}, [],
        "cloth.0.mesh.grid.resolution"),
    "unprefixed PETSc option": ({}, {}, ["-ksp_monitor"], "-ksp_monitor"),
    "unprefixed misspelt PETSc option": ({}, {}, ["-ksp_rtoll", "1e-8"], "-ksp_rtoll"),
    "gamg with baij on the command line": ({}, {}, ["-distcloth_pc_type", "gamg"],
                                           "-distcloth_pc_type"),
    "scene viewer writing a file": ({}, {"solver": {"ksp_view": "ascii:{tmp}/view.txt"}}, [],
                                    "solver.ksp_view"),
    "scene binary viewer": ({}, {"solver": {"ksp_monitor": "binary"}}, [],
                            "solver.ksp_monitor"),
    "time.end not a multiple of time.step": ({}, {"time": {"end": 0.015, "step": 0.01}}, [],
                                             "time.end"),
}
# one triangle: 3 vertices for 4 ranks
RANKS = {"more ranks than vertices": 4}


def launch(args, cwd, ranks=2):
    cmd = [str(ROOT / "scripts" / "mpiexec.sh"), str(ranks), sys.executable, "-m", "distcloth",
           *map(str, args)]
    return subprocess.run(cmd, env=clean_env(), cwd=cwd, capture_output=True, text=True,
                          timeout=240)


def prepare(tmp_path, files, changes, extra):
    for name, content in files.items():
        path = tmp_path / name
        path.parent.mkdir(parents=True, exist_ok=True)
        (path.write_bytes if isinstance(content, bytes) else path.write_text)(content)
    (tmp_path / "dir.h5").mkdir(exist_ok=True)
    text = yaml.safe_dump({**TINY, **changes}).replace("{tmp}", str(tmp_path))
    (tmp_path / "scene.yaml").write_text(text)
    return [a.replace("{tmp}", str(tmp_path)) for a in extra]


def outputs(tmp_path):
    """Result files the run left (besides the ones a case put there on purpose)."""
    return sorted(p.name for p in tmp_path.rglob("*") if p.suffix in (".h5", ".xdmf")
                  and p.is_file() and p.read_bytes()[:8] == b"\x89HDF\r\n\x1a\n")


@pytest.mark.rank0_only
@pytest.mark.parametrize("case", list(CASES))
def test_bad_input_is_one_line_and_exit_2(tmp_path, case):
    files, changes, extra, key = CASES[case]
    args = prepare(tmp_path, files, changes, extra)
    for command in ("check", "run"):
        p = launch([command, "scene.yaml", *args], tmp_path, RANKS.get(case, 2))
        assert p.returncode == 2, (command, p.returncode, p.stderr[-3000:])
        assert "Traceback" not in p.stderr and "MPI_ABORT" not in p.stderr, p.stderr[-3000:]
        lines = [ln for ln in p.stderr.splitlines() if ln.startswith("distcloth")]
        assert len(lines) == 1 and lines[0].startswith("distcloth: config error: "), p.stderr
        assert key in lines[0], lines[0]
        assert outputs(tmp_path) == [], (command, outputs(tmp_path))


@pytest.mark.rank0_only
def test_overwrite_replaces_an_existing_result(tmp_path):
    prepare(tmp_path, {}, {}, [])
    assert launch(["run", "scene.yaml", "--quiet"], tmp_path).returncode == 0
    first = (tmp_path / "out" / "tiny.h5").stat().st_mtime_ns
    p = launch(["run", "scene.yaml", "--quiet"], tmp_path)
    assert p.returncode == 2 and "--overwrite" in p.stderr
    assert (tmp_path / "out" / "tiny.h5").stat().st_mtime_ns == first
    p = launch(["run", "scene.yaml", "--quiet", "--overwrite"], tmp_path)
    assert p.returncode == 0, p.stderr[-3000:]
    assert (tmp_path / "out" / "tiny.h5").stat().st_mtime_ns != first


@pytest.mark.rank0_only
def test_options_writing_files_are_taken_from_the_command_line(tmp_path):
    # refused from a scene (above), a viewer to a file is the user's own choice here
    prepare(tmp_path, {}, {}, [])
    p = launch(["check", "scene.yaml", "-log_view", f":{tmp_path}/log.txt"], tmp_path)
    assert p.returncode == 0, p.stderr[-3000:]


@pytest.mark.rank0_only
def test_study_refuses_every_variant_before_the_reference(tmp_path):
    prepare(tmp_path, {}, {}, [])
    p = launch(["study", "accuracy", "scene.yaml", "--vary", "time.step=0.003,0.007",
                "--dir", tmp_path / "study"], tmp_path)
    assert p.returncode == 2, p.stderr[-3000:]
    assert "nothing to compare" in p.stderr and "Traceback" not in p.stderr
    assert outputs(tmp_path) == []         # the reference never ran


def test_coincident_vertices_are_welded_and_parts_reported(tmp_path):
    # two triangles of a square split along their diagonal, as an exporter writes a UV seam
    from distcloth.config import load_config
    from distcloth.scene import build_model
    (tmp_path / "seam.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\n"
                                       "f 1 2 3\nf 4 6 5\n")
    scene = {**TINY, "cloth": [{**TINY["cloth"][0], "mesh": {"file": "seam.obj"},
                                "pins": [{"indices": [0, 5]}]}]}
    (tmp_path / "scene.yaml").write_text(yaml.safe_dump(scene))
    model = build_model(load_config(str(tmp_path / "scene.yaml")))
    assert model.rest_positions.shape[0] == 4 and model.triangles.max() == 3
    assert list(model.pinned) == [0, 3]          # the file's vertex 5 is the welded mesh's 3
    assert any("welded 2 of 6" in note for note in model.load_notes)
    apart = build_model(load_config(str(tmp_path / "scene.yaml"), ["cloth.0.mesh.weld=false"]))
    assert apart.rest_positions.shape[0] == 6
    assert any("2 separate parts" in note for note in apart.load_notes)


def test_a_write_failing_on_one_rank_fails_the_run_on_all(shared_tmp, comm, monkeypatch):
    # a full disk seen by the last rank only at step 2: every rank stops there,
    # the file says failed with the cause, exit status 1, no rank left waiting
    import errno

    import h5py

    from distcloth.config.load import config_from_dict
    from distcloth.io.h5writer import ResultWriter
    from distcloth.linalg.petsc import init_petsc
    from distcloth.parallel.comm import Comm
    from distcloth.run import run
    init_petsc([])
    write_step = ResultWriter.write_step

    def full_disk(self, step, *args, **kwargs):
        if step == 2 and comm.Get_rank() == comm.Get_size() - 1:
            raise OSError(errno.ENOSPC, "No space left on device")
        return write_step(self, step, *args, **kwargs)

    monkeypatch.setattr(ResultWriter, "write_step", full_disk)
    raw = {**TINY, "time": {"end": 0.05, "step": 0.01},
           "output": {"file": str(shared_tmp / "full.h5"), "every": 0.01, "preview": False}}
    cfg = config_from_dict(raw, str(shared_tmp), "full.yaml")
    assert run(cfg, Comm(comm), quiet=True, progress=False) == 1
    comm.barrier()
    with h5py.File(shared_tmp / "full.h5", "r") as f:
        assert f.attrs["status"] == "failed" and int(f.attrs["error_step"]) == 2
        assert "No space left on device" in f.attrs["error"]
