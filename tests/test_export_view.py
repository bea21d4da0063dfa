"""``distcloth export`` and ``distcloth view``: every written file is read back
and compared with the result file's frames.

The result files are written serially (ResultWriter without a communicator)
in each rank's own temporary directory, so the tests run the same under
``mpiexec -n 2 pytest`` and alone; the tests that launch processes
(the command line, a real run, headless Chromium) run on rank 0.
"""
from __future__ import annotations

import os
import re
import shutil
import subprocess
import textwrap

import h5py
import numpy as np
import pytest

from conftest import clean_env, run_cli
from distcloth.config import ConfigError
from distcloth.io import ResultWriter
from distcloth.io.export import export, read_pc2
from distcloth.io.frames import parse_frames
from distcloth.scene.meshio import read_mesh
from distcloth.scene.uvs import read_obj_uvs

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")


class MovingBody:
    """A collider surface as collision/surfaces.py makes them: a triangle
    sliding along x (or a static one)."""

    def __init__(self, name, speed):
        self.name, self.shape, self.moving, self.speed = name, "mesh", speed != 0, speed
        self.triangles = np.array([[0, 1, 2]], dtype=np.int64)

    def vertices(self, t):
        return np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]) \
            + [self.speed * t, 0.0, 0.0]


def grid_cloth(nx=6, ny=5):
    u, v = np.meshgrid(np.linspace(0, 1, nx), np.linspace(0, 1, ny), indexing="ij")
    rest = np.stack([u.ravel(), v.ravel(), np.full(u.size, 1.0)], axis=1)
    idx = np.arange(nx * ny).reshape(nx, ny)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    triangles = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return rest, triangles


def write_result(path, n_frames=5, uv=True, colliders=()):
    """A small result: a grid falling and waving, with per-corner UVs (every
    triangle corner its own coordinate, as at a seam) unless ``uv=False``."""
    rest, triangles = grid_cloth()
    n = rest.shape[0]
    arrays = {}
    if uv:
        arrays = {"mesh/uv": np.random.default_rng(1).random((3 * triangles.shape[0], 2)),
                  "mesh/uv_index": np.arange(3 * triangles.shape[0]).reshape(-1, 3)}
    w = ResultWriter(path, None, rest_positions=rest, triangles=triangles,
                     owned_input=np.arange(n), part=np.zeros(n, np.int32), config_text="x",
                     attrs={"scene": "export test"}, stage_names=["solve"],
                     diagnostic_names=["kinetic_energy"], colliders=list(colliders),
                     arrays=arrays)
    frames = []
    for k in range(n_frames):
        x = rest + [0.0, 0.0, -0.1 * k] + 0.05 * np.sin(3 * rest[:, :1] + k) * [0, 0, 1]
        # digits a %.9g format would lose: the OBJ must keep float64 exactly
        x = x + 1e-13 * np.arange(n)[:, None]
        w.write_step(k, 0.1 * k, {"kinetic_energy": 0.0}, {"solve": 0.0}, {"solve": 1})
        w.write_frame(k, 0.1 * k, x)
        frames.append(x)
    w.close()
    return np.array(frames), triangles, arrays


# ---------------------------------------------------------------- --frames

def test_frames_spec():
    assert parse_frames("all", 4).tolist() == [0, 1, 2, 3]
    assert parse_frames("last", 4).tolist() == [3]
    assert parse_frames("0:2", 4).tolist() == [0, 1]
    assert parse_frames("1:", 4).tolist() == [1, 2, 3]
    assert parse_frames("::2, last", 5).tolist() == [0, 2, 4]
    assert parse_frames("-1,0", 4).tolist() == [0, 3]
    assert parse_frames("2", 4).tolist() == [2]
    for bad in ("4", "-5", "x", "1:2:0", "5:9", "", "1-3"):
        with pytest.raises(ConfigError) as err:
            parse_frames(bad, 4)
        assert err.value.key == "--frames"


# ---------------------------------------------------------------- round trips

def test_obj_frames_round_trip_with_uvs(tmp_path):
    path = str(tmp_path / "r.h5")
    frames, triangles, arrays = write_result(path)
    written = export(path, "obj", "1:4", str(tmp_path / "obj"))
    assert [os.path.basename(p) for p in written] == ["r_0001.obj", "r_0002.obj", "r_0003.obj"]
    for k, p in zip((1, 2, 3), written):
        check_obj(p, frames[k], triangles, arrays)        # exact: %.17g


def check_obj(path, vertices, triangles, arrays):
    """The OBJ's vertices, triangles and per-corner UVs are the given ones."""
    got, tri = read_mesh(path)
    np.testing.assert_array_equal(got, vertices)
    np.testing.assert_array_equal(tri, triangles)
    with open(path, encoding="ascii") as handle:
        uv, uv_index = read_obj_uvs(handle.read())
    np.testing.assert_array_equal(uv[uv_index], arrays["mesh/uv"][arrays["mesh/uv_index"]])


def test_obj_without_uvs_and_one_file(tmp_path):
    path = str(tmp_path / "r.h5")
    frames, triangles, _ = write_result(path, uv=False)
    (p,) = export(path, "obj", "last", str(tmp_path / "last.obj"))
    vertices, tri = read_mesh(p)
    np.testing.assert_array_equal(vertices, frames[-1])
    with open(p, encoding="ascii") as handle:
        assert read_obj_uvs(handle.read()) is None


def test_ply_frames_round_trip(tmp_path):
    path = str(tmp_path / "r.h5")
    frames, triangles, _ = write_result(path)
    written = export(path, "ply", "all")         # default: r_ply/ beside the result
    assert len(written) == frames.shape[0]
    for k, p in enumerate(written):
        assert os.path.dirname(p) == str(tmp_path / "r_ply")
        with open(p, "rb") as handle:
            assert b"format binary_little_endian 1.0\n" in handle.read(200)
        vertices, tri = read_mesh(p)
        np.testing.assert_array_equal(vertices, frames[k])
        np.testing.assert_array_equal(tri, triangles)


def test_pc2_round_trip_and_rest_mesh(tmp_path):
    path = str(tmp_path / "r.h5")
    frames, triangles, arrays = write_result(path)
    cache, rest_obj = export(path, "pc2", "0:5:2", str(tmp_path / "cloth.pc2"))
    with open(cache, "rb") as handle:
        head = handle.read(32)
    assert head[:12] == b"POINTCACHE2\0"
    pc2 = read_pc2(cache)
    assert pc2["positions"].dtype == np.float32 and pc2["positions"].shape == (3, 30, 3)
    assert (pc2["start"], pc2["sample_rate"]) == (0.0, 1.0)
    np.testing.assert_array_equal(pc2["positions"], frames[[0, 2, 4]].astype(np.float32))
    # the rest mesh the modifier goes on: the same vertices, in the same order
    with h5py.File(path, "r") as f:
        check_obj(rest_obj, f["mesh/rest_positions"][...], triangles, arrays)


def test_existing_files_refused_then_overwritten(tmp_path):
    path = str(tmp_path / "r.h5")
    write_result(path)
    target = str(tmp_path / "one.ply")
    export(path, "ply", "0", target)
    before = os.path.getmtime(target)
    with pytest.raises(ConfigError) as err:
        export(path, "ply", "1", target)
    assert err.value.key == "--output" and "--overwrite" in err.value.allowed
    export(path, "ply", "1", target, overwrite=True)
    assert os.path.getmtime(target) >= before
    assert sorted(os.listdir(tmp_path)) == ["one.ply", "r.h5", "r.xdmf"]   # no temporary left


# ---------------------------------------------------------------- UVs from the scene

OBJ_WITH_UVS = """\
# a quad and a triangle, the quad fan-triangulated; uv seam between them
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 2 0 0
vt 0 0
vt 1 0
vt 1 1
vt 0 1
vt 0.5 0.5
f 1/1 2/2/1 3/3 4/4
f 2/-1 5/5 3/3
"""


def test_obj_uvs_follow_the_triangles():
    uv, index = read_obj_uvs(OBJ_WITH_UVS)
    assert index.tolist() == [[0, 1, 2], [0, 2, 3], [4, 4, 2]]
    np.testing.assert_array_equal(uv[4], [0.5, 0.5])
    assert read_obj_uvs(OBJ_WITH_UVS.replace("f 2/-1 5/5 3/3", "f 2 5 3")) is None
    with pytest.raises(ValueError):
        read_obj_uvs(OBJ_WITH_UVS.replace("5/5", "5/9"))


@pytest.mark.rank0_only
def test_run_keeps_the_mesh_files_uvs(tmp_path):
    """An OBJ cloth with UVs, run, exported: the OBJ has the file's UVs."""
    rng = np.random.default_rng(0)
    nx = 5
    v = [f"v {i / (nx - 1)} {j / (nx - 1)} 1.0" for i in range(nx) for j in range(nx)]
    vt = [f"vt {a:.6f} {b:.6f}" for a, b in rng.random((nx * nx, 2))]
    f = []
    for i in range(nx - 1):
        for j in range(nx - 1):
            a, b, c, d = (1 + i * nx + j, 1 + (i + 1) * nx + j, 2 + (i + 1) * nx + j,
                          2 + i * nx + j)
            f += [f"f {a}/{a} {b}/{b} {c}/{c}", f"f {a}/{a} {c}/{c} {d}/{d}"]
    mesh = tmp_path / "sheet.obj"
    mesh.write_text("\n".join(v + vt + f) + "\n")
    scene = tmp_path / "s.yaml"
    scene.write_text(textwrap.dedent(f"""\
        scene: uv
        cloth:
          - name: sheet
            mesh: {{file: {mesh}}}
            pins: [{{indices: [0]}}]
            material: {{model: mass_spring, density: 0.1, stretch: 100.0, shear: 10.0,
                        bending: 1.0e-5, damping: 0.0}}
        effects: [gravity, membrane]
        time: {{end: 0.02, step: 0.01, integrator: backward_euler}}
        output: {{file: {tmp_path / 'uv.h5'}, every: 0.01, preview: false}}
        """))
    res = run_cli(["run", scene, "--quiet"], ranks=None, timeout=600)
    assert res.returncode == 0, res.stderr
    out = run_cli(["export", tmp_path / "uv.h5", "--format", "obj", "--frames", "last",
                   "--output", tmp_path / "last.obj"], ranks=None)
    assert out.returncode == 0, out.stderr
    expected_uv, expected_index = read_obj_uvs(mesh.read_text())
    uv, index = read_obj_uvs((tmp_path / "last.obj").read_text())
    np.testing.assert_array_equal(uv[index], expected_uv[expected_index])


# ---------------------------------------------------------------- command line

def cli(args) -> int:
    """``distcloth ARGS`` in this process (export and view need no MPI or PETSc)."""
    from distcloth.cli import main
    try:
        return main([str(a) for a in args])
    except SystemExit as exc:
        return exc.code


@pytest.mark.rank0_only
def test_cli_export(tmp_path):
    path = tmp_path / "r.h5"
    frames, _, _ = write_result(str(path))
    ok = run_cli(["export", path, "--format", "pc2", "--frames", "last"], ranks=None)
    assert ok.returncode == 0, ok.stderr
    assert ok.stdout.split() == [str(tmp_path / "r.pc2"), str(tmp_path / "r_rest.obj")]
    assert read_pc2(tmp_path / "r.pc2")["positions"].shape == (1,) + frames.shape[1:]


def test_cli_bad_arguments(tmp_path, capsys):
    path = tmp_path / "r.h5"
    write_result(str(path))
    export(str(path), "pc2", "last")
    bad = [["export", path, "--format", "stl"],
           ["export", path, "--format", "obj", "--frames", "7"],
           ["export", path, "--format", "obj", "--frames", "0:x"],
           ["export", tmp_path / "missing.h5", "--format", "ply"],
           ["export", tmp_path / "r.pc2", "--format", "ply"],
           ["export", path, "--format", "pc2", "--output", tmp_path / "c.obj"],
           ["export", path, "--format", "obj", "--output", tmp_path / "two.obj"],
           ["export", path, "--format", "pc2"],            # exists already
           ["export", path, "--format", "ply", "--output", tmp_path / "r.h5"],
           ["export", path, "--format", "ply", "-log_view"],
           ["export", path],
           ["view", path, "--output", tmp_path / "page.txt"],
           ["view", path, "--frames", "last:"]]
    before = sorted(os.listdir(tmp_path))
    capsys.readouterr()
    for args in bad:
        code = cli(args)
        err = capsys.readouterr().err
        assert code == 2, (args, err)
        assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, (args, err)
    assert sorted(os.listdir(tmp_path)) == before


# ---------------------------------------------------------------- viewer

def chromium() -> str | None:
    return shutil.which("chromium") or shutil.which("chromium-browser")


def headless(url: str, *args, timeout=120) -> subprocess.CompletedProcess:
    """Chromium without a display.  As root it needs --no-sandbox; WebGL comes
    from SwiftShader, Chromium's software GPU, when there is no real one."""
    cmd = [chromium(), "--headless", "--no-sandbox", "--disable-gpu-sandbox",
           "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--hide-scrollbars",
           "--no-first-run", "--disable-extensions", "--window-size=480,360",
           "--virtual-time-budget=3000", *args, url]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout,
                          env=clean_env(HOME=os.path.dirname(url[len("file://"):])))


@pytest.mark.rank0_only
def test_viewer_plays_in_headless_chromium(tmp_path):
    # Debian's chromium is installed by scripts/setup.sh: a missing one is a failure
    assert chromium(), "chromium is not installed (scripts/setup.sh installs it)"
    import matplotlib.image as mpimg
    path = tmp_path / "r.h5"
    write_result(str(path), n_frames=6, colliders=[MovingBody("plate", 2.0),
                                                   MovingBody("wall", 0.0)])
    res = run_cli(["view", path, "--output", tmp_path / "page.html"], ranks=None)
    assert res.returncode == 0, res.stderr
    html = (tmp_path / "page.html").read_text()
    assert "http://" not in html.split("<script", 1)[0]     # nothing fetched to show it
    assert not re.search(r"<script[^>]+src=", html) and "<link" not in html
    url = "file://" + str(tmp_path / "page.html")

    # the page moves its slider to the URL's frame: no error, and it says so
    dom = headless(f"{url}#frame=5", "--dump-dom")
    status = re.search(r'<div id="status"[^>]*>([^<]*)</div>', dom.stdout)
    assert status, dom.stdout[-2000:] + dom.stderr[-2000:]
    assert status.group(1) == "ok frame=5 frames=6", status.group(1)
    shots = []
    for frame in (0, 5):
        png = tmp_path / f"frame{frame}.png"
        headless(f"{url}#frame={frame}", f"--screenshot={png}")
        assert png.exists(), "no screenshot"
        shots.append(mpimg.imread(str(png))[..., :3])
    for shot in shots:
        # not blank: the cloth's colour is on a good part of the canvas
        orange = (shot[..., 0] > 0.6) & (shot[..., 1] < 0.55) & (shot[..., 2] < 0.45)
        assert orange.mean() > 0.01, orange.mean()
    changed = np.abs(shots[0] - shots[1]).max(axis=2) > 0.1
    assert changed.mean() > 0.005, changed.mean()
