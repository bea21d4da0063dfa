"""Scene files -> SceneConfig: values, defaults, overrides and the exact
one-line errors of docs/config.md."""
import copy
import dataclasses

import pytest
import yaml

from distcloth.config import (ConfigError, SceneConfig, config_from_dict, format_config_error,
                              load_config)
from distcloth.config.load import apply_overrides, own_option_names
from distcloth.config.schema import (ClothSpec, GridSpec, LinearSystemSpec, MaterialSpec, MeshSpec,
                                     OutputSpec, PinSpec, TimeSpec)

FULL_SCENE = """\
scene: hanging_square
cloth:
  - name: square
    mesh:
      grid: {size: [0.5, 0.25], resolution: [51, 26], pattern: regular}
      center: [0, 0, 1.0]
      rotation: [90, 0, 0]
    pins:
      - edge: top
      - corner: top_left
      - indices: [0, 17]
      - box: {min: [-1, -1, 0.9], max: [1, 1, 1.1]}
    material: {model: mass_spring, density: 0.2, stretch: 12, shear: 3.0,
               bending: 2.0e-6, damping: 0.01}
  - name: shirt
    mesh: {file: meshes/shirt.OBJ, scale: 2}
    pins: [{indices: [5]}]
effects: [gravity, membrane, drag]
gravity: [0, 0, -9.8]
drag: 0.5
time: {end: 2.0, step: 1e-2, integrator: symplectic_euler, newton_iterations: 3,
       newton_tolerance: 1.0e-6}
solver: {ksp_type: gmres, ksp_rtol: 1e-8, ksp_max_it: 50, ksp_monitor: true}
linear_system: {mat_type: aij}
output: {file: out/./hanging.h5, every: 0.1, preview: false}
"""


def grid_piece(**extra) -> dict:
    return {"mesh": {"grid": {"size": [1, 1], "resolution": [2, 2]}}, **extra}


def base_scene() -> dict:
    """A small valid scene as raw data: one 2x2 grid piece and a file piece."""
    return {"cloth": [grid_piece(name="a"), {"name": "b", "mesh": {"file": "m.obj"}}],
            "time": {"end": 1.0, "step": 0.01}}


def set_path(raw: dict, path: str, value) -> dict:
    """``raw`` with the value at a dotted path replaced (test-side, independent
    of the loader's override code)."""
    *parents, last = [int(p) if p.isdigit() else p for p in path.split(".")]
    node = raw
    for part in parents:
        node = node[part]
    node[last] = value
    return raw


def error_line(raw: dict, base_dir) -> str:
    with pytest.raises(ConfigError) as caught:
        config_from_dict(raw, str(base_dir), "scene.yaml")
    return format_config_error(caught.value)


@pytest.fixture
def scene_dir(tmp_path):
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "shirt.OBJ").write_text("v 0 0 0\n")
    (tmp_path / "m.obj").write_text("v 0 0 0\n")
    (tmp_path / "m.stl").write_text("")
    (tmp_path / "hanging.yaml").write_text(FULL_SCENE)
    return tmp_path


def test_full_scene_gives_the_written_values(scene_dir):
    config = load_config(str(scene_dir / "hanging.yaml"))
    expected = SceneConfig(
        scene="hanging_square",
        cloth=(
            ClothSpec(
                name="square",
                mesh=MeshSpec(grid=GridSpec((0.5, 0.25), (51, 26), "regular"),
                              center=(0.0, 0.0, 1.0), rotation=(90.0, 0.0, 0.0)),
                pins=(PinSpec(edge="top"), PinSpec(corner="top_left"), PinSpec(indices=(0, 17)),
                      PinSpec(box_min=(-1.0, -1.0, 0.9), box_max=(1.0, 1.0, 1.1))),
                material=MaterialSpec("mass_spring", 0.2, 12.0, 3.0, 2.0e-6, 0.01)),
            ClothSpec(name="shirt",
                      mesh=MeshSpec(file=str(scene_dir / "meshes" / "shirt.OBJ"), scale=2.0),
                      pins=(PinSpec(indices=(5,)),)),
        ),
        effects=("gravity", "membrane", "drag"),
        gravity=(0.0, 0.0, -9.8),
        drag=0.5,
        # resolved: not an energy-momentum scheme; no contact effect, so the predictor
        time=TimeSpec(2.0, 0.01, "symplectic_euler", 3, 1.0e-6, adaptive=False,
                      require_newton_convergence=False, linearise_at="predictor"),
        solver=(("ksp_type", "gmres"), ("pc_type", "bjacobi"), ("sub_pc_type", "sor"),
                ("ksp_rtol", 1e-8), ("ksp_max_it", 50), ("ksp_monitor", True)),
        linear_system=LinearSystemSpec(mat_type="aij"),
        output=OutputSpec(file="out/hanging.h5", every=0.1, preview=False),
    )
    assert dataclasses.replace(config, source_text="") == expected
    assert all(type(x) is float for x in config.gravity + config.cloth[0].mesh.grid.size)
    assert config.cloth[0].material.shear_stiffness == 3.0


def test_defaults_fill_everything_not_given(tmp_path):
    config = config_from_dict({"cloth": {"mesh": {"grid": {"size": [1, 2], "resolution": [3, 4]}}}},
                              str(tmp_path), "some/dir/drape.yaml")
    assert dataclasses.replace(config, source_text="") == SceneConfig(
        scene="drape",
        cloth=(ClothSpec(name="piece0", mesh=MeshSpec(grid=GridSpec((1.0, 2.0), (3, 4)))),),
        time=TimeSpec(linearise_at="predictor"))    # resolved: no contact effect
    assert config.cloth[0].mesh.grid.pattern == "alternating"
    assert config.cloth[0].material.shear_stiffness == 1.0
    # no solver: section: the preset by problem size (linalg/presets.py) decides
    assert config.solver_options == {}
    assert config.linear_system.mat_type is None and config.linear_system.warm_start is None


def test_null_sections_mean_defaults(tmp_path):
    raw = {"cloth": [grid_piece(material=None, pins=None)],
           "time": None, "solver": None, "output": None, "effects": None}
    config = config_from_dict(raw, str(tmp_path), "x.yaml")
    assert config.time == TimeSpec(linearise_at="predictor") and config.output == OutputSpec()
    assert config.cloth[0].material == MaterialSpec() and config.cloth[0].pins == ()


def test_yaml_anchors_and_merge_keys_still_work(tmp_path):
    path = tmp_path / "merge.yaml"
    path.write_text("cloth:\n"
                    "  - {name: a, mesh: {grid: &g {size: [1, 1], resolution: [2, 2]}}}\n"
                    "  - {name: b, mesh: {grid: {<<: *g, resolution: [3, 3]}}}\n")
    config = load_config(str(path))
    assert [piece.mesh.grid.resolution for piece in config.cloth] == [(2, 2), (3, 3)]


@pytest.mark.parametrize("text, value", [("1e-5", 1e-5), ("2E3", 2000.0), ("-15e-1", -1.5)])
def test_float_strings_are_accepted_where_floats_are_wanted(tmp_path, text, value):
    # PyYAML reads 1e-5 (no dot) as a string
    raw = yaml.safe_load(f"cloth: {{mesh: {{grid: {{size: [1, 1], resolution: [2, 2]}}}}}}\n"
                         f"gravity: [0, 0, {text}]\n")
    assert isinstance(raw["gravity"][2], str)
    assert config_from_dict(raw, str(tmp_path), "x.yaml").gravity == (0.0, 0.0, value)


def test_resolved_source_text_loads_back_to_an_equal_config(scene_dir):
    config = load_config(str(scene_dir / "hanging.yaml"), ["time.end=3"])
    assert "\n" in config.source_text and "end: 3.0" in config.source_text
    again = config_from_dict(yaml.safe_load(config.source_text), "/", "elsewhere.yaml")
    assert again == config


THE_EFFECTS = ("one of gravity | membrane | bending | damping | drag | collisions | self_collision | "
               "strain_limiting | loads")
TIME_KEYS = ("end, step, integrator, newton_iterations, newton_tolerance, newmark_beta, "
             "newmark_gamma, energy_momentum, adaptive, max_halvings, max_strain, energy_guard, max_energy_gain, "
             "energy_retry_newton, energy_retry_until, require_newton_convergence, linearise_at")

# (key path set on base_scene(), value, the expected line after 'config error: ')
ERRORS = [
    ("cloth.1.mesh.file", "missing.obj",
     "cloth.1.mesh.file: 'missing.obj' — an existing .obj or .ply file "
     "(not found: {dir}/missing.obj)"),
    ("cloth.1.mesh.file", "m.stl", "cloth.1.mesh.file: 'm.stl' — an existing .obj or .ply file"),
    ("cloth.0.material", {"density": -0.1},
     "cloth.0.material.density: -0.1 — a finite number > 0"),
    ("cloth.0.material", {"shear": -1}, "cloth.0.material.shear: -1 — a finite number >= 0"),
    ("cloth.0.material", {"model": "shell"},
     "cloth.0.material.model: 'shell' — one of mass_spring | fem"),
    ("cloth.0.material", {"model": "fem", "E_weft": 100, "E_warp": 50, "nu_weft": 0.3,
                          "nu_warp": 0.3},
     "cloth.0.material.nu_warp: 0.3 — nu_warp = nu_weft * E_warp / E_weft = 0.15 (otherwise "
     "the stiffness of the EG07 tutorial, Part 1 Eq. 22 is not symmetric)"),
    ("cloth.0.material", {"model": "fem", "E_weft": 100, "E_warp": 100, "nu_weft": 1.2},
     "cloth.0.material.nu_warp: 1.2 — nu_weft * nu_warp < 1"),
    ("cloth.0.material", {"E_weft": 100}, "cloth.0.material.E_weft: 100 — only with model: fem "
                                          "(mass_spring uses stretch, shear and flexion springs)"),
    ("cloth.0.material", {"model": "fem", "bending_model": "flexion"},
     "cloth.0.material.bending_model: 'flexion' — grid_lines, dihedral, isometric, dihedral_shell or isometric_shell with model: fem"),
    ("cloth.0.material", {"stretch": True},
     "cloth.0.material.stretch: true — a finite number > 0"),
    ("solver", {"pc_type": "gamg"}, "linear_system.mat_type: 'baij' — aij with solver.pc_type: "
                                     "gamg (PETSc's GAMG cannot build its graph from a BAIJ "
                                     "matrix, the default)"),
    ("time", {"max_energy_gain": 0}, "time.max_energy_gain: 0 — a finite number > 0"),
    ("time", {"energy_guard": "yes"}, "time.energy_guard: 'yes' — true or false"),
    ("time", {"require_newton_convergence": 1},
     "time.require_newton_convergence: 1 — true or false"),
    ("effects", ["gravity", "wind"], f"effects.1: 'wind' — {THE_EFFECTS}"),
    ("effects", ["drag", "drag"], "effects.1: 'drag' — each effect at most once"),
    ("effects", "gravity", "effects: 'gravity' — a list of effect names: gravity, membrane, "
                           "bending, damping, drag, collisions, self_collision, strain_limiting, "
                           "loads"),
    ("time", {"stepp": 0.01},
     f"time.stepp: 0.01 — unknown key (did you mean step?); allowed keys: {TIME_KEYS}"),
    ("colour", "red", "colour: 'red' — unknown key; allowed keys: scene, cloth, effects, "
                      "gravity, drag, time, solver, linear_system, output, drape, "
                      "contact, colliders, work_stealing, strain_limiting, garment"),
    ("time.step", "fast", "time.step: 'fast' — a finite number > 0"),
    ("time.step", 2.0, "time.step: 2.0 — a number > 0 and <= time.end (1)"),
    ("time.end", float("inf"), "time.end: inf — a finite number > 0"),
    ("time", {"integrator": "rk5"},
     "time.integrator: 'rk5' — one of backward_euler | bdf2 | implicit_midpoint | newmark | "
     "symplectic_euler | explicit_midpoint | rk4"),
    ("time", {"newmark_beta": 0.6}, "time.newmark_beta: 0.6 — a finite number >= 0 and <= 0.5"),
    ("time", {"energy_retry_until": "never"},
     "time.energy_retry_until: 'never' — one of no_gain | converged"),
    ("time", {"newton_iterations": 0}, "time.newton_iterations: 0 — an integer >= 1 and <= 100"),
    ("time", {"newton_iterations": 2.0},
     "time.newton_iterations: 2.0 — an integer >= 1 and <= 100"),
    ("drag", float("nan"), "drag: nan — a finite number >= 0"),
    ("gravity", [0, -9.81], "gravity: [0, -9.81] — a list of 3 numbers"),
    ("cloth.0.mesh.grid.resolution", [2.0, 2],
     "cloth.0.mesh.grid.resolution.0: 2.0 — an integer >= 2"),
    ("cloth.0.mesh.grid.size", [1, 0], "cloth.0.mesh.grid.size.1: 0 — a finite number > 0"),
    ("cloth.0.mesh.grid", {"size": [1, 1]},
     "cloth.0.mesh.grid.resolution: null — required: [nu, nv] vertices"),
    ("cloth.0.mesh.grid.pattern", "random",
     "cloth.0.mesh.grid.pattern: 'random' — one of regular | alternating"),
    ("cloth.0.mesh.scale", 2, "cloth.0.mesh.scale: 2 — only for file meshes"),
    ("cloth.1.mesh.grid", {"size": [1, 1], "resolution": [2, 2]},
     "cloth.1.mesh: {file: 'm.obj', grid: {size: [1, 1], resolution: [2, 2]}}"
     " — exactly one of grid, file, pattern"),
    ("cloth.1.pins", [{"edge": "top"}],
     "cloth.1.pins.0.edge: 'top' — edge pins only on grid meshes; use indices or box"),
    ("cloth.0.pins", [{"corner": "top"}],
     "cloth.0.pins.0.corner: 'top' — one of bottom_left | bottom_right | top_left | top_right"),
    ("cloth.0.pins", [{"edge": "top", "corner": "top_left"}],
     "cloth.0.pins.0: {edge: 'top', corner: 'top_left'}"
     " — exactly one of edge, corner, indices, box"),
    ("cloth.0.pins", [{"edge": "left"}, {"indices": [0, 4]}],
     "cloth.0.pins.1.indices.1: 4 — a vertex index 0 <= i < 4 (the grid's vertex count)"),
    ("cloth.1.pins", [{"indices": [-1]}], "cloth.1.pins.0.indices.0: -1 — an integer >= 0"),
    ("cloth.0.pins", [{"box": {"min": [0, 0, 1], "max": [1, 1, 0]}}],
     "cloth.0.pins.0.box: {min: [0, 0, 1], max: [1, 1, 0]} — min <= max in every component"),
    ("cloth.1.name", "a", "cloth.1.name: 'a' — a name no other piece has (cloth.0 has it)"),
    ("cloth", [], "cloth: [] — a non-empty list of cloth pieces"),
    ("cloth", None, "cloth: null — a non-empty list of cloth pieces"),
    ("output", {"every": 0.001},
     "output.every: 0.001 — a number >= time.step (0.01): "
     "frames cannot be more frequent than steps"),
    ("output", {"file": "out/result.csv"},
     "output.file: 'out/result.csv' — a file name ending in .h5 or .hdf5"),
    ("output", {"preview": "yes"}, "output.preview: 'yes' — true or false"),
    ("solver", {"-ksp_rtol": 1e-8},
     "solver.-ksp_rtol: 1e-08 — a PETSc option without the leading '-': write ksp_rtol"),
    ("solver", {"distcloth_ksp_rtol": 1e-8},
     "solver.distcloth_ksp_rtol: 1e-08 — a PETSc option without the prefix distcloth_ "
     "(distcloth adds it): write ksp_rtol"),
    ("solver", {"ksp type": "cg"}, "solver.ksp type: 'cg' — a PETSc option name: "
                                   "letters, digits and _, starting with a letter"),
    ("solver", {"ksp_type": ["cg"]},
     "solver.ksp_type: ['cg'] — a string, a finite number or a boolean"),
    ("solver", {"mat_type": "aij"}, "solver.mat_type: 'aij' — moved: write linear_system.mat_type"),
    ("solver", {"warm_start": True}, "solver.warm_start: true — moved: write linear_system.warm_start"),
    ("solver", {"pc_rebuild_every": 2},
     "solver.pc_rebuild_every: 2 — moved: write linear_system.pc_rebuild_every"),
    ("linear_system", {"mat_type": "dense"}, "linear_system.mat_type: 'dense' — one of baij | aij"),
    ("linear_system", {"warm_start": 1}, "linear_system.warm_start: 1 — true or false"),
    ("linear_system", {"step_error_fraction": 0},
     "linear_system.step_error_fraction: 0 — a finite number > 0"),
    ("linear_system", {"pc_rebuild_every": 0},
     "linear_system.pc_rebuild_every: 0 — an integer >= 1"),
    ("linear_system", {"ksp_rtol": 1e-8}, "linear_system.ksp_rtol: 1e-08 — unknown key; allowed "
                                          "keys: mat_type, warm_start, pc_rebuild_every, step_error_fraction"),
    ("work_stealing", {"enabled": "yes"}, "work_stealing.enabled: 'yes' — true or false"),
    ("work_stealing", {"b": 0.5}, "work_stealing.b: 0.5 — a finite number >= 1"),
    ("work_stealing", {"chunk": 0}, "work_stealing.chunk: 0 — an integer >= 1"),
    ("strain_limiting", {"method": "pbd"}, "strain_limiting.method: 'pbd' — one of provot | velocity"),
    ("strain_limiting", {"weft": 0}, "strain_limiting.weft: 0 — a finite number > 0"),
    ("strain_limiting", {"passes": 0}, "strain_limiting.passes: 0 — an integer >= 1"),
    ("strain_limiting", {"rule": "average"},
     "strain_limiting.rule: 'average' — only with method: velocity"),
    ("cloth.0.material", {"model": "fem", "nu_weft": 0.3, "compression": 0.1},
     "cloth.0.material.compression: 0.1 — a fraction >= sqrt(nu_weft * nu_warp) = 0.3 (the "
     "Poisson coupling would make the energy fall under compression in both directions)"),
    ("cloth.0.material", {"model": "fem", "strain": "corotated", "compression": 0.5},
     "cloth.0.material.strain: 'corotated' — stvk with compression < 1 (the stiffness under "
     "compression is a branch of the tabulated stvk law)"),
    ("drape", {"criterion": "energy"},
     "drape.criterion: 'energy' — one of force | motion"),
    # grips, loads, initial velocities (docs/loads_and_grips.md)
    ("cloth.0.pins", [{"edge": "left", "motion": {"velocity": [1, 0, 0], "stop": 0}}],
     "cloth.0.pins.0.motion.stop: 0 — a finite number > 0"),
    ("cloth.0.pins", [{"edge": "left", "motion": {"velocity": [1, 0, 0], "start": 2, "stop": 1}}],
     "cloth.0.pins.0.motion.stop: 1.0 — a time > start (2 s), or null"),
    ("cloth.0.pins", [{"edge": "left", "motion": {"velocity": [1, 0, 0], "times": [0, 1]}}],
     "cloth.0.pins.0.motion: {velocity: [1, 0, 0], times: [0, 1]} — exactly one of velocity, "
     "times"),
    ("cloth.0.pins", [{"edge": "left", "motion": {"velocity": [1, 0]}}],
     "cloth.0.pins.0.motion.velocity: [1, 0] — a list of 3 numbers"),
    ("cloth.0.pins", [{"edge": "left", "motion": {"times": [0, 1], "translations": [[0, 0, 0]]}}],
     "cloth.0.pins.0.motion.translations: [[0, 0, 0]] — a list of 2 [x, y, z] vectors (one per "
     "time)"),
    ("cloth.0.pins", [{"edge": "left", "motion": {"times": [0, 1],
                                                  "rotations": [[0, 0, 1], [0, 0, 0]]}}],
     "cloth.0.pins.0.motion.rotations.0: [0.0, 0.0, 1.0] — [0, 0, 0]: a grip moves from where "
     "it starts (the first keyframe is its start pose)"),
    ("cloth.0.pins", [{"edge": "left", "motion": {"times": [1, 1]}}],
     "cloth.0.pins.0.motion.times.1: 1.0 — a time > 1 (times strictly increasing)"),
    ("cloth.0.pins", [{"edge": "left", "motion": {"times": [-1, 1]}}],
     "cloth.0.pins.0.motion.times.0: -1 — a finite number >= 0"),
    ("cloth.0.pins", [{"edge": "left", "motion": {"velocity": [1, 0, 0], "center": [0, 0, 0]}}],
     "cloth.0.pins.0.motion.center: [0, 0, 0] — only with times (a keyframed motion)"),
    ("cloth.0.pins", [{"edge": "left", "motion": {"times": [0, 1], "stop": 2}}],
     "cloth.0.pins.0.motion.stop: 2 — only with velocity (a constant-velocity motion)"),
    ("cloth.0.loads", [{"force": [0, 0, -1]}],
     "cloth.0.loads.0: {force: [0, 0, -1]} — exactly one of edge, corner, indices, box"),
    ("cloth.0.loads", [{"edge": "left"}],
     "cloth.0.loads.0: {edge: 'left'} — exactly one of force, forces, line_force"),
    ("cloth.0.loads", [{"edge": "left", "forces": [[0, 0, 1]]}],
     "cloth.0.loads.0.forces: [[0, 0, 1]] — only with indices (one force per index); use force "
     "for the other selectors"),
    ("cloth.0.loads", [{"indices": [0, 1], "forces": [[0, 0, 1]]}],
     "cloth.0.loads.0.forces: [[0, 0, 1]] — a list of 2 [x, y, z] vectors (one per index)"),
    ("cloth.0.loads", [{"corner": "top_left", "force": [0, 0, -1], "ramp": -1}],
     "cloth.0.loads.0.ramp: -1 — a finite number >= 0"),
    ("cloth.0.loads", [{"corner": "top_left", "line_force": "down"}],
     "cloth.0.loads.0.line_force: 'down' — a list of 3 numbers"),
    ("cloth.1.loads", [{"edge": "top", "force": [0, 0, 1]}],
     "cloth.1.loads.0.edge: 'top' — edge loads only on grid meshes; use indices or box"),
    ("effects", ["gravity", "loads"],
     "effects: ['gravity', 'loads'] — the loads effect needs at least one entry under "
     "cloth.<i>.loads"),
    ("cloth.0.initial_velocity", [1, 0], "cloth.0.initial_velocity: [1, 0] — a list of 3 numbers"),
    ("cloth.0.initial_angular_velocity", [0, 0, "fast"],
     "cloth.0.initial_angular_velocity.2: 'fast' — a finite number"),
    ("output", {"reactions": "yes"}, "output.reactions: 'yes' — true or false"),
]


@pytest.mark.parametrize("path, value, expected", ERRORS, ids=[e[2].split(":")[0] for e in ERRORS])
def test_each_bad_value_names_its_key_path(scene_dir, path, value, expected):
    raw = set_path(base_scene(), path, value)
    assert error_line(raw, scene_dir) == ("distcloth: config error: "
                                          + expected.replace("{dir}", str(scene_dir)))


def test_a_grid_pin_edge_is_fine_on_a_grid_but_not_on_a_file(scene_dir):
    raw = set_path(base_scene(), "cloth.0.pins", [{"edge": "top"}, {"indices": [3]}])
    config = config_from_dict(raw, str(scene_dir), "x.yaml")
    assert config.cloth[0].pins == (PinSpec(edge="top"), PinSpec(indices=(3,)))


def test_overrides_are_applied_and_checked(scene_dir):
    config = load_config(str(scene_dir / "hanging.yaml"), [
        "time.step=0.05", "cloth.0.material.stretch=20", "cloth.1.pins.0.indices=[1, 2]",
        "solver.ksp_rtol=1e-10", "solver.pc_factor_levels=2", "gravity.2=-1",
        "output.preview=true", "scene=other"])
    assert config.time.step == 0.05
    assert config.cloth[0].material.stretch == 20.0
    assert config.cloth[1].pins == (PinSpec(indices=(1, 2)),)
    assert config.solver_options["ksp_rtol"] == 1e-10
    assert config.solver_options["pc_factor_levels"] == 2
    assert config.gravity == (0.0, 0.0, -1.0)
    assert config.output.preview is True and config.scene == "other"


def test_overrides_start_absent_sections_and_address_a_single_piece(tmp_path):
    raw = {"cloth": grid_piece()}
    result = apply_overrides(raw, ["time.end=5", "cloth.0.name=sheet"])
    assert result == {"cloth": [{**grid_piece(), "name": "sheet"}], "time": {"end": 5}}
    assert raw == {"cloth": grid_piece()}     # the input is left alone


TIME_ALLOWED = f"no such key; allowed under time: {TIME_KEYS}"

OVERRIDE_ERRORS = [
    ("time.stepp=0.1", f"time.stepp: 0.1 — {TIME_ALLOWED}"),
    ("nosuch.key=1", "nosuch.key: 1 — no such key; allowed under the top level: scene, cloth, "
                     "effects, gravity, drag, time, solver, linear_system, output, drape, "
                     "contact, colliders, work_stealing, strain_limiting, garment"),
    ("cloth.2.name=x", "cloth.2.name: 'x' — an index 0 <= i < 2: cloth has 2 element(s)"),
    ("cloth.first.name=x", "cloth.first.name: 'x' — an index 0 <= i < 2: cloth has 2 element(s)"),
    ("cloth.0.pins.0.edge=top", "cloth.0.pins.0.edge: 'top' — cloth.0.pins is not in the "
                                "scene: set it whole"),
    ("cloth.0.mesh.grid.size.x=1", "cloth.0.mesh.grid.size.x: 1 — an index 0 <= i < 2: "
                                   "cloth.0.mesh.grid.size has 2 element(s)"),
    ("solver.ksp_rtol.x=1", "solver.ksp_rtol.x: 1 — solver options take single values"),
    ("drag.0=1", "drag.0: 1 — drag is not in the scene: set it whole"),
    ("time.step", "--set: 'time.step' — key.path=value, e.g. time.step=0.01"),
    ("time.step=[1", "time.step: '[1' — a YAML value (expected ',' or ']', but got "
                     "'<stream end>')"),
    ("time..step=1", "--set: 'time..step=1' — key.path=value, e.g. time.step=0.01"),
    ("time.step=fast", "time.step: 'fast' — a finite number > 0"),
    ("cloth.0.material.density=-2", "cloth.0.material.density: -2 — a finite number > 0"),
    ("cloth.1.pins.0={edge: top}",
     "cloth.1.pins.0.edge: 'top' — edge pins only on grid meshes; use indices or box"),
]


@pytest.mark.parametrize("override, expected", OVERRIDE_ERRORS,
                         ids=[o[0] for o in OVERRIDE_ERRORS])
def test_bad_overrides_name_their_path(scene_dir, override, expected):
    raw = set_path(base_scene(), "cloth.1.pins", [{"indices": [0]}])
    with pytest.raises(ConfigError) as caught:
        config_from_dict(apply_overrides(raw, [override]), str(scene_dir), "x.yaml")
    assert format_config_error(caught.value) == "distcloth: config error: " + expected


NOT_A_MAPPING = ("null — a YAML mapping with keys scene, cloth, effects, gravity, drag, time, "
                 "solver, linear_system, output, drape, contact, colliders, work_stealing, strain_limiting, garment")


@pytest.mark.parametrize("text, expected", [
    ("cloth: [a\n", "\"expected ',' or ']', but got '<stream end>'\" — valid YAML "
                    "(error at line 2, column 1)"),
    ("", NOT_A_MAPPING),
    ("# all commented out\n", NOT_A_MAPPING),
    ("[1, 2]\n", NOT_A_MAPPING.replace("null", "[1, 2]")),
    ("time: {end: 1}\ntime: {step: 1}\n",
     "'found duplicate key time' — valid YAML (error at line 2, column 1)"),
])
def test_a_file_that_is_not_a_yaml_mapping_is_named(tmp_path, text, expected):
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError) as caught:
        load_config(str(path))
    assert format_config_error(caught.value) == f"distcloth: config error: {path}: {expected}"


def test_a_missing_scene_file_is_named(tmp_path):
    with pytest.raises(ConfigError) as caught:
        load_config(str(tmp_path / "none.yaml"))
    assert format_config_error(caught.value) == (
        f"distcloth: config error: {tmp_path}/none.yaml: 'No such file or directory'"
        " — a readable YAML scene file")


@pytest.mark.parametrize("value, shown", [
    ("two\nlines", "'two\\nlines'"),
    (list(range(100)), "[0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16, …"),
    ({"a": None, "b": [True, 1.5]}, "{a: null, b: [true, 1.5]}"),
])
def test_the_error_is_one_short_line(value, shown):
    line = format_config_error(ConfigError("time.step", value, "a\nnumber"))
    assert line == f"distcloth: config error: time.step: {shown} — a number"
    assert "\n" not in line and len(line) < 130


def test_a_self_referencing_value_still_formats():
    loop: list = []
    loop.append(loop)
    line = format_config_error(ConfigError("effects", loop, "a list"))
    assert line.startswith("distcloth: config error: effects: [[[[") and line.endswith("— a list")


def test_the_raw_input_is_not_modified(scene_dir):
    raw = base_scene()
    before = copy.deepcopy(raw)
    config_from_dict(raw, str(scene_dir), "x.yaml")
    assert raw == before


def test_fabric_presets(tmp_path):
    """Every preset gives a valid continuum material, is marked with its source
    (a citation or 'illustrative'), and single values override it."""
    from distcloth.config.fabrics import FABRICS
    from distcloth.config.load import config_from_dict
    for name, values in FABRICS.items():
        assert values["source"] == "illustrative" or "Table" in values["source"], name
        raw = {"cloth": [{"mesh": {"grid": {"size": [1, 1], "resolution": [3, 3]}},
                          "material": {"preset": name, "bending": 3e-5}}]}
        m = config_from_dict(raw, str(tmp_path), "x.yaml").cloth[0].material
        assert m.model == "fem" and m.preset == name and m.bending == 3e-5
        assert m.density == values["density"] and m.E_weft == values["E_weft"]
        e_weft, e_warp, nu_weft, nu_warp, _ = m.orthotropic()
        assert abs(nu_weft * e_warp - nu_warp * e_weft) < 1e-12 * e_weft
    bad = {"cloth": [{"mesh": {"grid": {"size": [1, 1], "resolution": [3, 3]}},
                      "material": {"preset": "kevlar"}}]}
    with pytest.raises(ConfigError, match="cloth.0.material.preset"):
        config_from_dict(bad, str(tmp_path), "x.yaml")


# --- colliders (collisions effect) ---------------------------------------------------

def collider_scene(*colliders, effects=("gravity", "collisions")) -> dict:
    raw = base_scene()
    raw["effects"] = list(effects)
    raw["colliders"] = list(colliders)
    return raw


SPHERE = {"name": "ball", "shape": "sphere", "center": [0, 0, 0], "radius": 0.25}


def test_colliders_are_read_with_defaults_and_motion(scene_dir):
    moving = {**SPHERE, "name": "m", "friction": 0.3, "thickness": 0.001,
              "motion": {"times": [0, 1], "translations": [[0, 0, 0], [1, 0, 0]]}}
    plane = {"name": "floor", "shape": "plane", "normal": [0, 0, 2], "offset": 0}
    raw = collider_scene(SPHERE, moving, plane)
    raw["cloth"][0]["thickness"] = 0.002
    cfg = config_from_dict(raw, str(scene_dir), "scene.yaml")
    ball, m, floor = cfg.colliders
    assert (ball.shape, dict(ball.geometry), ball.friction, ball.thickness, ball.motion) == \
        ("sphere", {"center": (0.0, 0.0, 0.0), "radius": 0.25}, 0.0, 0.0, None)
    assert m.motion.times == (0.0, 1.0) and m.motion.rotations == ((0.0, 0.0, 0.0),) * 2
    assert dict(floor.geometry)["normal"] == (0.0, 0.0, 2.0)
    assert cfg.cloth[0].thickness == 0.002 and cfg.cloth[1].thickness == ClothSpec.thickness
    # the resolved text reads back to the same configuration
    again = config_from_dict(yaml.safe_load(cfg.source_text), str(scene_dir), "scene.yaml")
    assert dataclasses.replace(again, source_text="") == dataclasses.replace(cfg, source_text="")


def test_colliders_without_the_effect_are_still_checked(scene_dir):
    cfg = config_from_dict(collider_scene(SPHERE, effects=("gravity",)), str(scene_dir), "s.yaml")
    assert len(cfg.colliders) == 1 and not cfg.has("collisions")
    bad = collider_scene({**SPHERE, "radius": 0}, effects=("gravity",))
    assert error_line(bad, scene_dir).startswith("distcloth: config error: colliders.0.radius: 0")


COLLIDER_ERRORS = [
    ([], "effects: ['gravity', 'collisions'] — the collisions effect needs at least one entry"),
    ([{**SPHERE, "radius": -1}], "colliders.0.radius: -1 — a finite number > 0"),
    ([{**SPHERE, "shape": "cone"}], "colliders.0.shape: 'cone' — one of plane | sphere | capsule | box"),
    ([{**SPHERE, "normal": [0, 0, 1]}], "colliders.0.normal: [0, 0, 1] — not a key of a sphere"),
    ([{**SPHERE, "centre": [0, 0, 0]}], "colliders.0.centre: [0, 0, 0] — unknown key (did you mean center?)"),
    ([{**SPHERE, "center": [0, 0]}], "colliders.0.center: [0, 0] — a list of 3 numbers"),
    ([{"shape": "plane", "normal": [0, 0, 0], "offset": 0}],
     "colliders.0.normal: [0.0, 0.0, 0.0] — a non-zero direction"),
    ([{"shape": "plane", "normal": [0, 0, 1]}], "colliders.0.offset: null — required"),
    ([{"shape": "box", "center": [0, 0, 0], "half_extents": [1, 0, 1]}],
     "colliders.0.half_extents.1: 0 — a finite number > 0"),
    ([{"shape": "capsule", "a": [0, 0, 0], "b": [1, 0, 0], "radius": 0.1, "friction": -0.1}],
     "colliders.0.friction: -0.1 — a finite number >= 0"),
    ([{**SPHERE, "thickness": -1e-3}], "colliders.0.thickness: -0.001 — a finite number >= 0"),
    ([SPHERE, SPHERE], "colliders.1.name: 'ball' — a name no other collider has (colliders.0 has it)"),
    ([{**SPHERE, "motion": {"times": [0, 1], "translations": [[0, 0, 0]]}}],
     "colliders.0.motion.translations: [[0, 0, 0]] — a list of 2 [x, y, z] vectors"),
    ([{**SPHERE, "motion": {"times": [1, 0]}}], "colliders.0.motion.times.1: 0.0 — a time > 1"),
    ([{**SPHERE, "motion": {"times": [0, 1], "rotations": [[0, 0], [0, 0, 1]]}}],
     "colliders.0.motion.rotations.0: [0, 0] — a list of 3 numbers"),
]


@pytest.mark.parametrize("colliders, expected", COLLIDER_ERRORS,
                         ids=[e[1].split(":")[0] + str(i) for i, e in enumerate(COLLIDER_ERRORS)])
def test_bad_colliders_name_their_key_path(scene_dir, colliders, expected):
    assert error_line(collider_scene(*colliders), scene_dir).startswith(
        "distcloth: config error: " + expected)


MESH = {"name": "body", "shape": "mesh", "file": "m.obj"}


def test_mesh_colliders_are_placed_with_defaults(scene_dir):
    plain, placed, moved = config_from_dict(collider_scene(
        MESH, {**MESH, "name": "a", "center": [0, 0, 1], "rotation": [0, 0, 90], "up_axis": "y",
               "scale": 2},
        {**MESH, "name": "b", "translation": [1, 2, 3]}), str(scene_dir), "s.yaml").colliders
    assert (plain.up_axis, plain.rotation, plain.translation, plain.geometry) == \
        ("z", (0.0, 0.0, 0.0), None, ())
    assert (placed.up_axis, placed.rotation, dict(placed.geometry), placed.scale) == \
        ("y", (0.0, 0.0, 90.0), {"center": (0.0, 0.0, 1.0)}, 2.0)
    assert (moved.translation, moved.geometry) == ((1.0, 2.0, 3.0), ())
    # the resolved text reads back to the same placement
    cfg = config_from_dict(collider_scene(MESH, {**MESH, "name": "a", "center": [0, 0, 1],
                                                 "rotation": [0, 0, 90], "up_axis": "y"},
                                          {**MESH, "name": "b", "translation": [1, 2, 3]}),
                           str(scene_dir), "s.yaml")
    again = config_from_dict(yaml.safe_load(cfg.source_text), str(scene_dir), "s.yaml")
    assert again.colliders == cfg.colliders


MESH_PLACEMENT_ERRORS = [
    ({**MESH, "center": [0, 0, 1], "translation": [1, 0, 0]},
     "colliders.0.translation: [1, 0, 0] — not with center: center moves the bounding-box centre "
     "to a point, translation moves the mesh by a vector; give one"),
    ({**MESH, "up_axis": "x"}, "colliders.0.up_axis: 'x' — one of y | z"),
    ({**MESH, "up_axis": "Y"}, "colliders.0.up_axis: 'Y' — one of y | z"),
    ({**MESH, "rotation": [0, 90]}, "colliders.0.rotation: [0, 90] — a list of 3 numbers"),
    ({**MESH, "rotation": [0, "a", 0]}, "colliders.0.rotation.1: 'a' — a finite number"),
    ({**MESH, "translation": 1.0}, "colliders.0.translation: 1.0 — a list of 3 numbers"),
    ({**MESH, "center": [0, 0]}, "colliders.0.center: [0, 0] — a list of 3 numbers"),
    ({**SPHERE, "up_axis": "y"},
     "colliders.0.up_axis: 'y' — not a key of a sphere; a sphere takes center, radius"),
    ({**SPHERE, "rotation": [0, 0, 90]},
     "colliders.0.rotation: [0, 0, 90] — not a key of a sphere; a sphere takes center, radius"),
    ({"shape": "plane", "normal": [0, 0, 1], "offset": 0, "translation": [0, 0, 1]},
     "colliders.0.translation: [0, 0, 1] — not a key of a plane; a plane takes normal, offset"),
    ({"shape": "box", "center": [0, 0, 0], "half_extents": [1, 1, 1], "up_axis": "z"},
     "colliders.0.up_axis: 'z' — not a key of a box; a box takes center, half_extents"),
]


@pytest.mark.parametrize("collider, expected", MESH_PLACEMENT_ERRORS,
                         ids=[e[1].split(" — ")[0] + str(i)
                              for i, e in enumerate(MESH_PLACEMENT_ERRORS)])
def test_bad_mesh_placement_is_one_line(scene_dir, collider, expected):
    assert error_line(collider_scene(collider), scene_dir) == "distcloth: config error: " + expected


def test_cloth_thickness_must_not_be_negative(scene_dir):
    raw = set_path(base_scene(), "cloth.0.thickness", -0.001)
    assert error_line(raw, scene_dir) == ("distcloth: config error: cloth.0.thickness: -0.001"
                                          " — a finite number >= 0")


# --- linear_system: distcloth's own solver settings, also on the command line -------

def test_linear_system_is_read_and_gamg_takes_aij(scene_dir):
    raw = base_scene()
    raw["solver"] = {"pc_type": "gamg"}
    raw["linear_system"] = {"mat_type": "aij", "warm_start": True, "pc_rebuild_every": 4}
    config = config_from_dict(raw, str(scene_dir), "x.yaml")
    assert config.linear_system == LinearSystemSpec("aij", True, 4)
    assert "mat_type" not in config.solver_options and config.solver_options["pc_type"] == "gamg"
    # unset: the solver preset by size decides (linalg/presets.py)
    assert config_from_dict(base_scene(), str(scene_dir), "x.yaml").linear_system == \
        LinearSystemSpec(None, None, 1)


def test_command_line_options_set_linear_system_and_win(scene_dir):
    assert own_option_names() == ("mat_type", "warm_start", "pc_rebuild_every",
                                  "step_error_fraction")
    config = load_config(str(scene_dir / "hanging.yaml"), ["linear_system.pc_rebuild_every=2"],
                         {"warm_start": "true", "pc_rebuild_every": "3"})
    # the scene's mat_type stays; the command line wins over the file and --set
    assert config.linear_system == LinearSystemSpec("aij", True, 3)


@pytest.mark.parametrize("options, expected", [
    ({"mat_type": "dense"}, "command line -distcloth_mat_type: 'dense' — one of baij | aij"),
    ({"warm_start": "maybe"}, "command line -distcloth_warm_start: 'maybe' — true or false"),
    ({"pc_rebuild_every": "0"}, "command line -distcloth_pc_rebuild_every: 0 — an integer >= 1"),
    ({"mat_type": "[1"}, "command line -distcloth_mat_type: '[1' — a YAML value (expected ',' "
                         "or ']', but got '<stream end>')"),
])
def test_a_bad_command_line_option_is_named(scene_dir, options, expected):
    with pytest.raises(ConfigError) as caught:
        load_config(str(scene_dir / "hanging.yaml"), (), options)
    assert format_config_error(caught.value) == "distcloth: config error: " + expected


def test_a_bad_scene_value_is_not_blamed_on_the_command_line(scene_dir):
    with pytest.raises(ConfigError) as caught:
        load_config(str(scene_dir / "hanging.yaml"), ["linear_system.mat_type=dense"],
                    {"warm_start": "true"})
    assert caught.value.key == "linear_system.mat_type"


def test_a_solve_aimed_at_the_step_error_needs_the_unpreconditioned_residual(scene_dir):
    # the fraction bounds the solve's error through |b - A dv|: a scene's own
    # solver must stop on that residual; the size presets do
    raw = base_scene()
    raw["linear_system"] = {"step_error_fraction": 0.5}
    assert config_from_dict(raw, str(scene_dir), "x.yaml").linear_system.step_error_fraction == 0.5
    raw["solver"] = {"ksp_rtol": 1e-6}
    with pytest.raises(ConfigError) as caught:
        config_from_dict(raw, str(scene_dir), "x.yaml")
    assert str(caught.value) == (
        "linear_system.step_error_fraction: 0.5 — null unless solver.ksp_norm_type is "
        "unpreconditioned (the fraction bounds the solve's error through |b - A dv|; the size "
        "presets stop on it)")
    raw["solver"]["ksp_norm_type"] = "unpreconditioned"
    config_from_dict(raw, str(scene_dir), "x.yaml")
