"""XDMF sidecar that makes a result file's frames a time series in ParaView
(its Xdmf3 readers and the legacy XDMF reader) and meshio.

The light data (XML) only points into the HDF5 file.  Every frame is a
Uniform grid whose Topology is ``/mesh/triangles`` and whose Geometry is
frame k of ``/frames/positions``.  The readers differ in what they accept
(checked with ParaView 5.11 and meshio 5.3): the Xdmf3 readers and meshio
read no HyperSlab DataItem (Xdmf3 gives 0 points, meshio fails), so every
per-frame item names a 2-D dataset of its own, ``frame_view(dataset, k)``:
a virtual dataset the writer makes for each frame (h5writer.py), mapping
onto row k of the 3-D dataset, so nothing is stored twice.

meshio's ``TimeSeriesReader`` takes the mesh (points, cells) from the first
grid of the *last* temporal collection in the Domain and, per step, only the
grids' Attributes: so the cloth's collection comes last (each collider's
collection, another block in ParaView, before it), and the positions are
also an Attribute, ``position``, beside the fields.  The HDF5 file is
referenced by its bare name: the sidecar sits beside it and the pair can be
moved together.
"""
from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from xml.sax.saxutils import quoteattr
from dataclasses import dataclass
from typing import Sequence

import h5py
import numpy as np

_NUMBER_TYPES = {("Float", 8): "f8", ("Float", 4): "f4", ("Int", 8): "i8",
                 ("Int", 4): "i4", ("Int", 1): "i1", ("UInt", 8): "u8", ("UInt", 4): "u4",
                 ("Char", 1): "i1", ("UChar", 1): "u1"}

VIEWS = "/xdmf"     # the group of the per-frame virtual datasets


def frame_view(dataset: str, k: int) -> str:
    """Path of the 2-D virtual dataset that is row k of ``dataset``, a
    (frames, ...) dataset: ``/xdmf/frames/positions/000003`` for frame 3 of
    ``/frames/positions``."""
    return f"{VIEWS}{dataset}/{int(k):06d}"


@dataclass(frozen=True)
class XdmfAttribute:
    """A field shown on every frame's grid.

    ``dims`` are the dataset's dimensions without the frame axis; when
    ``per_frame`` the dataset has a leading frame axis and frame k's view
    (``frame_view``) is referenced.
    """
    name: str
    dataset: str                 # path inside the HDF5 file, e.g. "/partition/part"
    dims: tuple[int, ...]
    center: str = "Node"         # Node | Cell
    attribute_type: str = "Scalar"   # Scalar | Vector
    number_type: str = "Float"
    precision: int = 8
    per_frame: bool = False


@dataclass(frozen=True)
class XdmfBody:
    """A collider surface of the result file: ``group``/triangles (m, 3) and
    ``group``/positions, (frames, nv, 3) when ``moving``, else (1, nv, 3);
    either way its frames have views (a body that never moves: row 0's)."""
    name: str
    group: str                   # e.g. "/colliders/ball"
    n_vertices: int
    n_triangles: int
    moving: bool


def _dims(shape: Sequence[int]) -> str:
    return " ".join(str(int(d)) for d in shape)


def _hdf_item(parent, h5_filename, dataset, shape, number_type, precision):
    item = ET.SubElement(parent, "DataItem", Dimensions=_dims(shape), NumberType=number_type,
                         Precision=str(precision), Format="HDF")
    item.text = f"{h5_filename}:{dataset}"
    return item


def _surface_grid(name, t, h5_filename, triangles, n_triangles, positions, n_points):
    """A Uniform grid: triangles and XYZ points from two HDF datasets, at time t."""
    grid = ET.Element("Grid", Name=name, GridType="Uniform")
    ET.SubElement(grid, "Time", Value=repr(float(t)))
    topo = ET.SubElement(grid, "Topology", TopologyType="Triangle",
                         NumberOfElements=str(int(n_triangles)))
    _hdf_item(topo, h5_filename, triangles, (n_triangles, 3), "Int", 8)
    geom = ET.SubElement(grid, "Geometry", GeometryType="XYZ")
    _hdf_item(geom, h5_filename, positions, (n_points, 3), "Float", 8)
    return grid


def _attribute(grid, h5_filename, name, dataset, dims, center="Node", attribute_type="Scalar",
               number_type="Float", precision=8):
    attr = ET.SubElement(grid, "Attribute", Name=name, AttributeType=attribute_type, Center=center)
    _hdf_item(attr, h5_filename, dataset, dims, number_type, precision)


def _text(grid) -> str:
    """A frame's grid as indented XML, at its depth in the document."""
    ET.indent(grid, space=" ", level=3)
    return "   " + ET.tostring(grid, encoding="unicode").rstrip() + "\n"


class XdmfSeries:
    """The sidecar of a growing result: a temporal collection per collider,
    then the cloth's (see the module docstring).  ``append`` adds a frame,
    ``write`` writes the file; each frame is turned into XML once, so a
    rewrite costs a copy of its text, not a new serialisation of every
    frame (how often the result writer rewrites it: h5writer.py)."""

    def __init__(self, h5_filename: str, n_vertices: int, n_triangles: int,
                 extra_attributes: Sequence[XdmfAttribute] = (), bodies: Sequence[XdmfBody] = ()):
        self.h5 = h5_filename
        self.n_vertices, self.n_triangles = int(n_vertices), int(n_triangles)
        self.attributes = tuple(extra_attributes)
        self.bodies = tuple(bodies)
        self._bodies: list[list[str]] = [[] for _ in self.bodies]
        self._cloth: list[str] = []

    def __len__(self) -> int:
        """The number of frames appended."""
        return len(self._cloth)

    def append(self, t: float) -> None:
        """Frame k = the number appended so far, at time t; its views
        (``frame_view``) must exist in the HDF5 file."""
        k, h5 = len(self._cloth), self.h5
        for body, frames in zip(self.bodies, self._bodies):
            positions = frame_view(f"{body.group}/positions", k if body.moving else 0)
            frames.append(_text(_surface_grid(f"{body.name}_{k:06d}", t, h5,
                                              f"{body.group}/triangles", body.n_triangles,
                                              positions, body.n_vertices)))
        view = frame_view("/frames/positions", k)
        grid = _surface_grid(f"frame_{k:06d}", t, h5, "/mesh/triangles", self.n_triangles,
                             view, self.n_vertices)
        # meshio reads a step's Attributes only, never its Geometry
        _attribute(grid, h5, "position", view, (self.n_vertices, 3), attribute_type="Vector")
        for a in self.attributes:
            _attribute(grid, h5, a.name, frame_view(a.dataset, k) if a.per_frame else a.dataset,
                       a.dims, a.center, a.attribute_type, a.number_type, a.precision)
        self._cloth.append(_text(grid))

    def write(self, xdmf_path: str | os.PathLike) -> None:
        """Write the file to a temporary name and rename it, so a reader (or a
        crash) never sees half a file."""
        def collection(name, frames):
            return [f'  <Grid Name={quoteattr(name)} GridType="Collection" '
                    'CollectionType="Temporal">\n', *frames, "  </Grid>\n"]

        parts = ['<?xml version="1.0" ?>\n<!DOCTYPE Xdmf SYSTEM "Xdmf.dtd" []>\n',
                 '<Xdmf Version="3.0">\n <Domain>\n']
        for body, frames in zip(self.bodies, self._bodies):
            parts += collection(f"collider {body.name}", frames)
        parts += collection("cloth", self._cloth)
        parts.append(" </Domain>\n</Xdmf>\n")
        xdmf_path = os.fspath(xdmf_path)
        tmp = xdmf_path + ".tmp"
        with open(tmp, "w", encoding="utf-8") as fh:
            fh.write("".join(parts))
        os.replace(tmp, xdmf_path)


def write_xdmf(xdmf_path: str | os.PathLike, h5_filename: str, n_vertices: int,
               n_triangles: int, times: Sequence[float],
               extra_attributes: Sequence[XdmfAttribute] | None = None,
               bodies: Sequence[XdmfBody] = ()) -> None:
    """Write an XDMF 3 sidecar for ``len(times)`` frames at once (XdmfSeries).
    ``h5_filename`` should be the bare file name of the HDF5 file in the same
    folder."""
    series = XdmfSeries(h5_filename, n_vertices, n_triangles, extra_attributes or (), bodies)
    for t in times:
        series.append(t)
    series.write(xdmf_path)


def _parse_dims(text: str | None) -> tuple[int, ...] | None:
    if text is None:
        return None
    return tuple(int(x) for x in text.split())


def _virtual_problems(ds: h5py.Dataset, ref: str) -> list[str]:
    """A virtual dataset's sources must exist and contain what it maps: a
    mapping past a source's end reads as fill values, silently."""
    problems = []
    for vs in ds.virtual_sources():
        where = f"{ref}: virtual source {vs.file_name}:{vs.dset_name}"
        if vs.file_name != ".":
            problems.append(f"{where} is in another file")
            continue
        src = ds.file.get(vs.dset_name)
        if not isinstance(src, h5py.Dataset):
            problems.append(f"{where} is not a dataset")
            continue
        start, end = vs.src_space.get_select_bounds()
        if len(end) != len(src.shape) or any(e >= s for e, s in zip(end, src.shape)):
            problems.append(f"{where} selects {list(start)}..{list(end)} beyond its shape {src.shape}")
    return problems


def check_xdmf(xdmf_path: str | os.PathLike) -> list[str]:
    """Check an XDMF file against the HDF5 data it references.

    For every DataItem: it is in HDF or XML format, not a HyperSlab (which
    ParaView's Xdmf3 readers and meshio do not read); for HDF ones the file
    and dataset exist, the stated Dimensions equal the dataset's shape and
    NumberType/Precision its dtype, and a virtual dataset's sources exist
    and contain what it maps.  Also: triangle topologies hold
    NumberOfElements x 3 indices, XYZ geometries have 3 columns, node
    attributes one value per geometry point, cell attributes one per
    element, and times increase within each collection.  Returns the
    problems found (an empty list means valid).
    """
    xdmf_path = os.fspath(xdmf_path)
    folder = os.path.dirname(os.path.abspath(xdmf_path))
    problems: list[str] = []
    try:
        root = ET.parse(xdmf_path).getroot()
    except (ET.ParseError, OSError) as err:
        return [f"cannot parse {xdmf_path}: {err}"]
    files: dict[str, h5py.File] = {}

    def dataset(ref: str):
        """The dataset for 'file.h5:/path', or None (problem recorded)."""
        fname, _, dpath = ref.strip().partition(":")
        if not dpath:
            problems.append(f"HDF reference {ref.strip()!r} is not 'file:/dataset'")
            return None
        if fname not in files:
            full = os.path.join(folder, fname)
            try:
                files[fname] = h5py.File(full, "r")
            except OSError as err:
                problems.append(f"cannot open {full}: {err}")
                files[fname] = None
        f = files[fname]
        if f is None:
            return None
        obj = f.get(dpath)
        if not isinstance(obj, h5py.Dataset):
            problems.append(f"{fname}:{dpath} is not a dataset")
            return None
        return obj

    def item_shape(item) -> tuple[int, ...] | None:
        """The shape an item stands for, after checking it against its data."""
        dims = _parse_dims(item.get("Dimensions"))
        where = (item.text or "").strip() or item.get("ItemType", "DataItem")
        if dims is None:
            problems.append(f"DataItem {where}: no Dimensions")
            return None
        if item.get("ItemType", "Uniform") != "Uniform" or item.find("DataItem") is not None:
            problems.append(f"DataItem of ItemType {item.get('ItemType')!r}: ParaView's Xdmf3 "
                            "readers and meshio read only plain HDF or XML items")
            return dims
        fmt = item.get("Format", "XML")
        if fmt not in ("HDF", "XML"):
            problems.append(f"DataItem {where}: Format {fmt!r} (HDF or XML)")
        if fmt == "HDF":
            ds = dataset(item.text or "")
            if ds is None:
                return dims
            ref = item.text.strip()
            if tuple(ds.shape) != dims:
                problems.append(f"{ref}: Dimensions {dims} but dataset shape {ds.shape}")
            key = (item.get("NumberType", "Float"), int(item.get("Precision", "4")))
            want = _NUMBER_TYPES.get(key)
            if want is None or np.dtype(want) != ds.dtype.newbyteorder("="):
                problems.append(f"{ref}: NumberType/Precision {key} but dtype {ds.dtype}")
            if ds.is_virtual:
                problems.extend(_virtual_problems(ds, ref))
        return dims

    try:
        grids = [g for g in root.iter("Grid") if g.get("GridType", "Uniform") == "Uniform"]
        if not grids:
            problems.append("no Uniform grid")
        parent = {child: p for p in root.iter() for child in p}
        last_time: dict[int, float] = {}     # per enclosing collection: the cloth, each collider
        for g in grids:
            name = g.get("Name", "?")
            t = g.find("Time")
            if t is not None:
                value = float(t.get("Value"))
                series = id(parent.get(g))
                if not value > last_time.get(series, -np.inf):
                    problems.append(f"grid {name}: time {value} does not increase")
                last_time[series] = value
            n_points = n_cells = None
            geom = g.find("Geometry")
            if geom is None or geom.find("DataItem") is None:
                problems.append(f"grid {name}: no Geometry data")
            else:
                shape = item_shape(geom.find("DataItem"))
                if shape is not None:
                    if geom.get("GeometryType", "XYZ") == "XYZ" and (len(shape) != 2 or shape[1] != 3):
                        problems.append(f"grid {name}: XYZ geometry of shape {shape}")
                    n_points = shape[0]
            topo = g.find("Topology")
            if topo is None or topo.find("DataItem") is None:
                problems.append(f"grid {name}: no Topology data")
            else:
                shape = item_shape(topo.find("DataItem"))
                n_el = topo.get("NumberOfElements")
                n_cells = int(n_el) if n_el is not None else (shape[0] if shape else None)
                if shape is not None and topo.get("TopologyType") == "Triangle" and (
                        len(shape) != 2 or shape[1] != 3 or (n_el is not None and int(n_el) != shape[0])):
                    problems.append(f"grid {name}: Triangle topology of shape {shape}, "
                                    f"NumberOfElements {n_el}")
            for attr in g.findall("Attribute"):
                item = attr.find("DataItem")
                shape = item_shape(item) if item is not None else None
                if shape is None:
                    continue
                expected = {"Node": (n_points, "points"), "Cell": (n_cells, "cells")}.get(
                    attr.get("Center", "Node"))
                if expected is None:
                    problems.append(f"grid {name}: attribute {attr.get('Name')} has Center "
                                    f"{attr.get('Center')!r} (Node or Cell)")
                elif expected[0] is not None and shape[0] != expected[0]:
                    problems.append(f"grid {name}: {attr.get('Center', 'Node').lower()} attribute "
                                    f"{attr.get('Name')} has {shape[0]} values for "
                                    f"{expected[0]} {expected[1]}")
    finally:
        for f in files.values():
            if f is not None:
                f.close()
    # one message per distinct problem: a bad shared dataset repeats per frame
    return list(dict.fromkeys(problems))
