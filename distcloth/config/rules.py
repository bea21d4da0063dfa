"""Rules that tie several keys of a scene together, one small function per
section type; everything a single field says about itself is in its
description (schema.py) and checked by walk.py.
"""
from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

from .checks import join
from .describe import entries, entry, needs
from .fabrics import FABRICS
from .schema import (FEM_ONLY, MESH_ONLY, OPTIONAL_SHAPE_KEYS, SHAPE_KEYS, ColliderGeometry,
                     ColliderSpec, ConfigError, FusedSpec, LoadSpec, MaterialSpec, MeshSpec,
                     MotionSpec, PinMotionSpec, PinSpec, SceneConfig, SewingSpec, TimeSpec)
from .walk import Context, Rules, read_field, required_text

PER_TIME = ("translations", "rotations")     # MotionSpec keys with one entry per time
# time.end / time.step may miss a whole number by floating-point rounding only
STEP_MULTIPLE_TOLERANCE = 1e-6
BARRIER_INTEGRATORS = ("backward_euler", "bdf2")


def _selector(pin, section: dict, key: str, ctx: Context):
    """Grid selectors need a grid; indices must exist on a grid (a file mesh's
    vertex count is known only once the scene builder reads it); a box needs
    both corners, in order (pins and loads)."""
    grid = ctx.parent["mesh"].grid
    for kind in ("edge", "corner"):
        if getattr(pin, kind) is not None and grid is None:
            raise ConfigError(join(key, kind), section[kind],
                              f"{kind} {'pins' if isinstance(pin, PinSpec) else 'loads'} only "
                              "on grid meshes; use indices or box")
    if pin.indices is not None and grid is not None:
        count = grid.resolution[0] * grid.resolution[1]
        for i, index in enumerate(pin.indices):
            if index >= count:
                raise ConfigError(join(join(key, "indices"), i), index,
                                  f"a vertex index 0 <= i < {count} (the grid's vertex count)")
    if section.get("box") is not None:
        for name in ("box_min", "box_max"):
            if getattr(pin, name) is None:
                e = entry(type(pin), name)
                raise ConfigError(join(key, e.key), None, required_text(e))
        if any(a > b for a, b in zip(pin.box_min, pin.box_max)):
            raise ConfigError(join(key, "box"), section["box"], "min <= max in every component")
    return pin


def _load(load: LoadSpec, section: dict, key: str, ctx: Context) -> LoadSpec:
    """A selected vertex set, and per-vertex forces only for listed indices."""
    load = _selector(load, section, key, ctx)
    if load.forces is not None:
        if load.indices is None:
            raise ConfigError(join(key, "forces"), section["forces"],
                              "only with indices (one force per index); use force for the "
                              "other selectors")
        if len(load.forces) != len(load.indices):
            raise ConfigError(join(key, "forces"), section["forces"],
                              f"a list of {len(load.indices)} [x, y, z] vectors (one per index)")
    return load


def _pin_motion(motion: PinMotionSpec, section: dict, key: str, ctx: Context) -> PinMotionSpec:
    """Keyframes start from where the pins are: the first pose is zero (a grip
    that jumped at t = 0 would be a teleport, not a motion); a velocity stops
    after it starts."""
    if motion.velocity is not None:
        if motion.stop is not None and motion.stop <= motion.start:
            raise ConfigError(join(key, "stop"), motion.stop,
                              f"a time > start ({motion.start:g} s), or null")
        return motion
    motion = _motion_zeros(motion, section, key, ctx)
    for name in PER_TIME:
        first = getattr(motion, name)[0]
        if any(c != 0.0 for c in first):
            raise ConfigError(join(join(key, name), 0), list(first),
                              "[0, 0, 0]: a grip moves from where it starts (the first "
                              "keyframe is its start pose)")
    return motion


def _mesh(mesh: MeshSpec, section: dict, key: str, ctx: Context) -> MeshSpec:
    """A pattern is placed by its own panels' placement (moved by translation),
    not by the grid and file keys."""
    if mesh.pattern is not None:
        for name in ("center", "rotation"):
            if section.get(name) is not None:
                raise ConfigError(join(key, name), section[name],
                                  "only for grid and file meshes: a pattern's panels are "
                                  "placed by the pattern; move it with translation")
    return mesh


def _fused(fused: FusedSpec, section: dict, key: str, ctx: Context) -> FusedSpec:
    box = (fused.box_min, fused.box_max)
    if (box[0] is None) != (box[1] is None):
        raise ConfigError(join(key, "box"), section.get("box"), "both min and max, or neither "
                          "(the whole panel)")
    if box[0] is not None and any(a > b for a, b in zip(*box)):
        raise ConfigError(join(key, "box"), section["box"], "min <= max in every component")
    return fused


def _sewing(sewing: SewingSpec, section: dict, key: str, ctx: Context) -> SewingSpec:
    if sewing.max_duration < sewing.duration:
        raise ConfigError(join(key, "max_duration"), sewing.max_duration,
                          f"a time >= sewing.duration ({sewing.duration:g} s)")
    return sewing


def _garment_pieces(config: SceneConfig) -> None:
    """Fused regions name pattern pieces; pattern pieces need a bending model
    a welded mesh can carry."""
    pieces = {spec.name: spec for spec in config.cloth}
    for i, fused in enumerate(config.garment.fused):
        spec = pieces.get(fused.piece)
        if spec is None or spec.mesh.pattern is None:
            names = [p.name for p in config.cloth if p.mesh.pattern is not None]
            raise ConfigError(f"garment.fused.{i}.piece", fused.piece,
                              "the name of a pattern piece (" + (", ".join(names) or "none")
                              + ")")
        if spec.material.model != "fem":
            raise ConfigError(f"garment.fused.{i}.piece", fused.piece,
                              "a piece with material.model: fem (a fused region adds moduli "
                              "to the continuum membrane)")
        if fused.bending > 0 and spec.material.bending <= 0:
            # the interlining's stiffness is a factor on the fabric's hinges
            raise ConfigError(f"garment.fused.{i}.bending", fused.bending,
                              f"0 when the fabric of piece {fused.piece!r} has no bending "
                              "stiffness (the interlining scales the fabric's)")
    for p, spec in enumerate(config.cloth):
        if spec.mesh.pattern is not None and spec.material.bending_kind.endswith("_shell"):
            raise ConfigError(f"cloth.{p}.material.bending_model", spec.material.bending_kind,
                              "dihedral or isometric for a pattern piece (shell stencils are "
                              "not carried across a welded seam)")


def _material_preset(section: dict, key: str, ctx: Context) -> dict:
    """A preset's values, a continuum membrane unless the scene says otherwise,
    and every value the scene gives on top."""
    preset = read_field(MaterialSpec, "preset", section, key, ctx)
    if preset is None:
        return section
    if section.get("model") not in (None, "fem"):
        raise ConfigError(join(key, "model"), section["model"],
                          "fem with a preset (presets are continuum fabrics)")
    base = {k: v for k, v in FABRICS[preset].items() if k != "source"}
    return {"model": "fem", **base, **{k: v for k, v in section.items() if v is not None}}


def _material(material: MaterialSpec, section: dict, key: str, ctx: Context) -> MaterialSpec:
    if material.model == "mass_spring":
        if material.bending_model not in (None, "flexion"):
            raise ConfigError(join(key, "bending_model"), section["bending_model"],
                              FEM_ONLY.message)
        return material
    if material.bending_model == "flexion":
        raise ConfigError(join(key, "bending_model"), "flexion",
                          "grid_lines, dihedral, isometric, dihedral_shell or isometric_shell "
                          "with model: fem")
    e_weft, e_warp, nu_weft, nu_warp, _ = material.orthotropic()
    # Eq. 22 of the EG07 tutorial, Part 1 is symmetric only when nu_weft E_warp = nu_warp E_weft
    if abs(nu_weft * e_warp - nu_warp * e_weft) > 1e-9 * max(nu_weft * e_warp, nu_warp * e_weft,
                                                             1e-300):
        raise ConfigError(join(key, "nu_warp"), nu_warp,
                          f"nu_warp = nu_weft * E_warp / E_weft = {nu_weft * e_warp / e_weft:.6g} "
                          "(otherwise the stiffness of the EG07 tutorial, Part 1 Eq. 22 is not "
                          "symmetric)")
    if nu_weft * nu_warp >= 1.0:
        raise ConfigError(join(key, "nu_warp"), nu_warp, "nu_weft * nu_warp < 1")
    curves = [e.key for e in entries(MaterialSpec) if e.setting.read == "curve"]
    if material.strain != "stvk" and any(getattr(material, c) is not None for c in curves):
        raise ConfigError(join(key, "strain"), material.strain,
                          "stvk with " + " / ".join(curves) + " tables")
    if material.strain != "stvk" and material.compression != 1.0:
        raise ConfigError(join(key, "strain"), material.strain,
                          "stvk with compression < 1 (the stiffness under compression is a "
                          "branch of the tabulated stvk law)")
    if material.compression < math.sqrt(nu_weft * nu_warp):
        # with both directions compressed the energy's Hessian in (e_weft, e_warp)
        # is [[c C11, C12], [C12, c C22]]: convex only for c^2 >= nu_weft nu_warp
        raise ConfigError(join(key, "compression"), material.compression,
                          f"a fraction >= sqrt(nu_weft * nu_warp) = "
                          f"{math.sqrt(nu_weft * nu_warp):.4g} (the Poisson coupling would "
                          "make the energy fall under compression in both directions)")
    return material


def _collider_keys(section: dict, key: str, ctx: Context) -> dict:
    """A shape takes its own geometry keys and, a mesh, the mesh keys; any
    other shape's key is refused before the values are read."""
    shape = read_field(ColliderSpec, "shape", section, key, ctx)
    mesh_keys = tuple(e.key for e in entries(ColliderSpec) if needs(ColliderSpec, e, MESH_ONLY))
    own = SHAPE_KEYS[shape] + OPTIONAL_SHAPE_KEYS.get(shape, ())
    takes = own + (tuple(k for k in mesh_keys if k not in own) if shape == "mesh" else ())
    for other in tuple(e.key for e in entries(ColliderGeometry)) + mesh_keys:
        if other not in takes and section.get(other) is not None:
            raise ConfigError(join(key, other), section[other],
                              f"not a key of a {shape}; a {shape} takes " + ", ".join(takes))
    return section


def _collider(spec: ColliderSpec, section: dict, key: str, ctx: Context) -> ColliderSpec:
    """Every required key of the shape given; a mesh sequence needs its frame
    rate; a mesh is moved by center or by translation, not both."""
    for name in SHAPE_KEYS[spec.shape]:
        if section.get(name) is None:
            e = next(e for t in (ColliderGeometry, ColliderSpec) for e in entries(t)
                     if e.key == name)
            raise ConfigError(join(key, name), None, required_text(e))
    given = dict(spec.geometry)
    own = SHAPE_KEYS[spec.shape] + OPTIONAL_SHAPE_KEYS.get(spec.shape, ())
    geometry = tuple((name, given[name]) for name in own if name in given)
    if spec.translation is not None and "center" in given:
        raise ConfigError(join(key, "translation"), section["translation"],
                          "not with center: center moves the bounding-box centre to a point, "
                          "translation moves the mesh by a vector; give one")
    if len(spec.files) > 1 and spec.frame_rate is None:
        raise ConfigError(join(key, "frame_rate"), None,
                          "frames per second (> 0): needed with a list of files")
    if len(spec.files) == 1 and spec.frame_rate is not None:
        raise ConfigError(join(key, "frame_rate"), spec.frame_rate,
                          "only with a list of files (a sequence)")
    return replace(spec, geometry=geometry)


def _motion_per_time(section: dict, key: str, ctx: Context, spec_type: type = MotionSpec) -> dict:
    """Times strictly increasing; one translation and one rotation per time."""
    times = read_field(spec_type, "times", section, key, ctx)
    if times is None:           # a pin motion by velocity
        return section
    for i in range(1, len(times)):
        if not times[i] > times[i - 1]:
            raise ConfigError(join(join(key, "times"), i), times[i],
                              f"a time > {times[i - 1]:g} (times strictly increasing)")
    for name in PER_TIME:
        raw = section.get(name)
        if raw is not None and (not isinstance(raw, list) or len(raw) != len(times)):
            raise ConfigError(join(key, name), raw,
                              f"a list of {len(times)} {entry(spec_type, name).setting.what}")
    return section


def _motion_zeros(motion: MotionSpec, section: dict, key: str, ctx: Context) -> MotionSpec:
    """Zero translations and rotations where none are given."""
    zeros = ((0.0, 0.0, 0.0),) * len(motion.times)
    return replace(motion, **{name: zeros for name in PER_TIME if not getattr(motion, name)})


def _time(time: TimeSpec, section: dict, key: str, ctx: Context) -> TimeSpec:
    if time.step > time.end:
        raise ConfigError(join(key, "step"), time.step,
                          f"a number > 0 and <= time.end ({time.end:g})")
    steps = time.end / time.step
    # a run is whole steps: an end between two steps would be rounded without a word
    if abs(steps - round(steps)) > STEP_MULTIPLE_TOLERANCE * max(1.0, steps):
        below, above = math.floor(steps), math.ceil(steps)
        raise ConfigError(join(key, "end"), time.end,
                          f"a whole number of steps of time.step ({time.step:g} s), e.g. "
                          f"{below * time.step:.10g} ({below} steps) or {above * time.step:.10g} "
                          f"({above} steps)")
    # an energy-momentum step conserves energy only when its Newton loop has
    # converged: by default such a step is rejected and halved instead of kept
    iterated = time.newton_iterations is None or time.newton_iterations > 1
    conserving = time.energy_momentum_scheme and iterated
    if time.require_newton_convergence is None:
        time = replace(time, require_newton_convergence=conserving)
    if time.adaptive is None:
        time = replace(time, adaptive=conserving)
    return time


def _scene(config: SceneConfig, section: dict, key: str, ctx: Context) -> SceneConfig:
    _unique_names(config.cloth, "cloth", "piece")
    for i, name in enumerate(config.effects):
        if name in config.effects[:i]:
            raise ConfigError(join("effects", i), name, "each effect at most once")
    if config.output.every < config.time.step:
        raise ConfigError("output.every", config.output.every,
                          f"a number >= time.step ({config.time.step:g}): frames cannot be more "
                          "frequent than steps")
    if config.solver_options.get("pc_type") == "gamg" and config.linear_system.mat_type != "aij":
        raise ConfigError("linear_system.mat_type", "baij", "aij with solver.pc_type: gamg "
                          "(PETSc's GAMG cannot build its graph from a BAIJ matrix, the "
                          "default)")
    fraction = config.linear_system.step_error_fraction
    if (fraction is not None and config.solver_options
            and config.solver_options.get("ksp_norm_type") != "unpreconditioned"):
        # the fraction bounds the solve's error through |b - A dv|; CG's
        # default, preconditioned, residual says nothing of it
        raise ConfigError("linear_system.step_error_fraction", fraction,
                          "null unless solver.ksp_norm_type is unpreconditioned (the "
                          "fraction bounds the solve's error through |b - A dv|; the size "
                          "presets stop on it)")
    if "collisions" in config.effects and not config.colliders:
        raise ConfigError("effects", list(config.effects),
                          "the collisions effect needs at least one entry under colliders:")
    for p, spec in enumerate(config.cloth):
        for k, pin in enumerate(spec.pins):
            if pin.motion is not None and spec.mesh.pattern is not None:
                raise ConfigError(f"cloth.{p}.pins.{k}.motion", "a motion",
                                  "null on a pattern piece (its vertices are renumbered when "
                                  "the garment is welded); pins of a pattern piece stay put")
    if "loads" in config.effects and not any(spec.loads for spec in config.cloth):
        raise ConfigError("effects", list(config.effects),
                          "the loads effect needs at least one entry under cloth.<i>.loads")
    _unique_names(config.colliders, "colliders", "collider")
    if config.contact.model == "barrier" and "collisions" in config.effects:
        _barrier_scene(config)
    _garment_pieces(config)
    config = _follow_skin(config)
    if config.time.linearise_at is None:
        # where contacts stop the cloth its predictor x0 + h v0 lies inside the
        # body and through its own folds: a sewn skirt linearised there never
        # settled on the hips (docs/integrators.md)
        contact = "collisions" in config.effects or "self_collision" in config.effects
        config = replace(config, time=replace(config.time,
                                              linearise_at="start" if contact else "predictor"))
    return _default_grid_bending(config)


def _barrier_scene(config: SceneConfig) -> None:
    error = barrier_misfit(config)
    if error is not None:
        raise error


def barrier_misfit(config: SceneConfig) -> ConfigError | None:
    """Why ``config`` could not run with ``contact.model: barrier`` (None: it
    could).  The barrier's Newton solve minimises the step's incremental
    potential: backward Euler's and BDF-2's (the other schemes' residuals are
    not its gradient); the bodies must answer distances (not image maps), and
    the contact distance must be positive for a default width."""
    if config.time.integrator not in BARRIER_INTEGRATORS:
        return ConfigError("time.integrator", config.time.integrator,
                           "backward_euler or bdf2 with contact.model: barrier")
    for i, spec in enumerate(config.colliders):
        if spec.shape == "mesh" and spec.method == "image":
            return ConfigError(f"colliders.{i}.method", "image",
                               "bvh with contact.model: barrier (image maps give no distance "
                               "field to a Newton iterate)")
    if config.contact.barrier_width is None:
        d = max(s.thickness for s in config.cloth) + max(c.thickness for c in config.colliders)
        if d <= 0.0:
            return ConfigError("contact.barrier_width", None, "a width in m > 0 (the cloth and "
                               "colliders have no thickness to take half of)")
    return None


def _follow_skin(config: SceneConfig) -> SceneConfig:
    """A skin-following region names a mesh collider (the only one, if it
    does not say); edge labels exist only on pattern pieces.  The collider's
    name is filled in, so the model builder has it."""
    meshes = [c.name for c in config.colliders if c.shape == "mesh"]
    cloth = list(config.cloth)
    for p, spec in enumerate(config.cloth):
        follow = spec.follow_skin
        if follow is None:
            continue
        key = f"cloth.{p}.follow_skin"
        if follow.edges and spec.mesh.pattern is None:
            raise ConfigError(f"{key}.edges", list(follow.edges),
                              "[] for a piece that is not a pattern (edge labels are the "
                              "pattern's)")
        name = follow.collider
        if name is None:
            if len(meshes) != 1:
                raise ConfigError(f"{key}.collider", None,
                                  "the name of the mesh collider to follow (the scene has "
                                  f"{len(meshes)} mesh colliders: " + (", ".join(meshes) or "none")
                                  + ")")
            name = meshes[0]
        elif name not in meshes:
            raise ConfigError(f"{key}.collider", name, "the name of a mesh collider ("
                              + (", ".join(meshes) or "none") + ")")
        cloth[p] = replace(spec, follow_skin=replace(follow, collider=name))
    return replace(config, cloth=tuple(cloth))


def _default_grid_bending(config: SceneConfig) -> SceneConfig:
    """``grid_lines`` only where every piece is a grid (one bending term per
    scene), and the fem default there: the continuum plate energy on the
    grid's lines and cells, exact for the Peirce strip on every grid pattern
    at the cost of the per-hinge sum (docs/fidelity.md)."""
    grids = all(spec.mesh.grid is not None for spec in config.cloth)
    for p, spec in enumerate(config.cloth):
        if spec.material.bending_model == "grid_lines" and not grids:
            other = next(q for q, s in enumerate(config.cloth) if s.mesh.grid is None)
            raise ConfigError(f"cloth.{p}.material.bending_model", "grid_lines",
                              "dihedral, isometric, dihedral_shell or isometric_shell: "
                              f"grid_lines needs every piece to be a grid (cloth.{other} "
                              "is not)")
    if not grids or not config.cloth:
        return config
    cloth = tuple(replace(spec, material=replace(spec.material, bending_model="grid_lines"))
                  if spec.material.model == "fem" and spec.material.bending_model is None
                  else spec for spec in config.cloth)
    return replace(config, cloth=cloth)


def _unique_names(items: tuple[Any, ...], key: str, noun: str) -> None:
    first: dict[str, int] = {}
    for i, item in enumerate(items):
        if item.name in first:
            raise ConfigError(join(join(key, i), "name"), item.name,
                              f"a name no other {noun} has ({key}.{first[item.name]} has it)")
        first[item.name] = i


RULES: dict[type, Rules] = {
    PinSpec: Rules(after=_selector),
    LoadSpec: Rules(after=_load),
    PinMotionSpec: Rules(before=lambda section, key, ctx: _motion_per_time(section, key, ctx,
                                                                           PinMotionSpec),
                         after=_pin_motion),
    MeshSpec: Rules(after=_mesh),
    FusedSpec: Rules(after=_fused),
    SewingSpec: Rules(after=_sewing),
    MaterialSpec: Rules(before=_material_preset, after=_material),
    ColliderSpec: Rules(before=_collider_keys, after=_collider),
    MotionSpec: Rules(before=_motion_per_time, after=_motion_zeros),
    TimeSpec: Rules(after=_time),
    SceneConfig: Rules(after=_scene),
}
