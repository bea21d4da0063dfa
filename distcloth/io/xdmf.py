"""XDMF sidecar that makes a result file's frames a time series in ParaView.

The light data (XML) only points into the HDF5 file: every frame is a Uniform
grid whose Topology is ``/mesh/triangles`` and whose Geometry is frame k of
``/frames/positions``, taken as a HyperSlab, so nothing is duplicated.  Each
collider is a second temporal collection with the same times, its surface
at frame k (row 0 for a body that never moves), so ParaView shows it as
another block.  The HDF5 file is referenced by its bare name: the sidecar
sits beside it and the pair can be moved together.
"""
from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from typing import Sequence

import h5py
import numpy as np

_NUMBER_TYPES = {("Float", 8): "f8", ("Float", 4): "f4", ("Int", 8): "i8",
                 ("Int", 4): "i4", ("UInt", 8): "u8", ("UInt", 4): "u4",
                 ("Char", 1): "i1", ("UChar", 1): "u1"}


@dataclass(frozen=True)
class XdmfAttribute:
    """A field shown on every frame's grid.

    ``dims`` are the dataset's dimensions without the frame axis; when
    ``per_frame`` the dataset has a leading frame axis and frame k's slab is
    referenced.
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
    ``group``/positions, (frames, nv, 3) when ``moving``, else (1, nv, 3)."""
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


def _hyperslab(parent, h5_filename, dataset, full_shape, k, number_type, precision):
    """Frame k of a (frames, ...) dataset: start (k, 0..), stride 1, count (1, rest)."""
    rest = tuple(full_shape[1:])
    slab = ET.SubElement(parent, "DataItem", ItemType="HyperSlab", Dimensions=_dims(rest),
                         Type="HyperSlab")
    sel = ET.SubElement(slab, "DataItem", Dimensions=f"3 {len(full_shape)}", Format="XML")
    sel.text = "\n".join([_dims((k,) + (0,) * len(rest)), _dims((1,) * len(full_shape)),
                          _dims((1,) + rest)])
    _hdf_item(slab, h5_filename, dataset, full_shape, number_type, precision)
    return slab


def write_xdmf(xdmf_path: str | os.PathLike, h5_filename: str, n_vertices: int,
               n_triangles: int, times: Sequence[float],
               extra_attributes: Sequence[XdmfAttribute] | None = None,
               bodies: Sequence[XdmfBody] = ()) -> None:
    """Write an XDMF 3 temporal collection for ``len(times)`` frames, and one
    per collider in ``bodies``.

    The file is written to a temporary name and renamed, so a reader (or a
    crash) never sees half a file.  ``h5_filename`` should be the bare file
    name of the HDF5 file in the same folder.
    """
    xdmf_path = os.fspath(xdmf_path)
    n_frames = len(times)
    root = ET.Element("Xdmf", Version="3.0")
    domain = ET.SubElement(root, "Domain")
    coll = ET.SubElement(domain, "Grid", Name="cloth", GridType="Collection",
                         CollectionType="Temporal")
    positions_shape = (n_frames, n_vertices, 3)
    for k, t in enumerate(times):
        grid = ET.SubElement(coll, "Grid", Name=f"frame_{k:06d}", GridType="Uniform")
        ET.SubElement(grid, "Time", Value=repr(float(t)))
        topo = ET.SubElement(grid, "Topology", TopologyType="Triangle",
                             NumberOfElements=str(int(n_triangles)))
        _hdf_item(topo, h5_filename, "/mesh/triangles", (n_triangles, 3), "Int", 8)
        geom = ET.SubElement(grid, "Geometry", GeometryType="XYZ")
        _hyperslab(geom, h5_filename, "/frames/positions", positions_shape, k, "Float", 8)
        for a in extra_attributes or ():
            attr = ET.SubElement(grid, "Attribute", Name=a.name, AttributeType=a.attribute_type,
                                 Center=a.center)
            if a.per_frame:
                _hyperslab(attr, h5_filename, a.dataset, (n_frames,) + tuple(a.dims), k,
                           a.number_type, a.precision)
            else:
                _hdf_item(attr, h5_filename, a.dataset, a.dims, a.number_type, a.precision)
    for body in bodies:
        series = ET.SubElement(domain, "Grid", Name=f"collider {body.name}", GridType="Collection",
                               CollectionType="Temporal")
        rows = n_frames if body.moving else 1
        for k, t in enumerate(times):
            grid = ET.SubElement(series, "Grid", Name=f"{body.name}_{k:06d}", GridType="Uniform")
            ET.SubElement(grid, "Time", Value=repr(float(t)))
            topo = ET.SubElement(grid, "Topology", TopologyType="Triangle",
                                 NumberOfElements=str(int(body.n_triangles)))
            _hdf_item(topo, h5_filename, f"{body.group}/triangles", (body.n_triangles, 3),
                      "Int", 8)
            geom = ET.SubElement(grid, "Geometry", GeometryType="XYZ")
            _hyperslab(geom, h5_filename, f"{body.group}/positions", (rows, body.n_vertices, 3),
                       k if body.moving else 0, "Float", 8)
    ET.indent(root, space=" ")
    tmp = xdmf_path + ".tmp"
    with open(tmp, "w", encoding="utf-8") as fh:
        fh.write('<?xml version="1.0" ?>\n<!DOCTYPE Xdmf SYSTEM "Xdmf.dtd" []>\n')
        fh.write(ET.tostring(root, encoding="unicode"))
        fh.write("\n")
    os.replace(tmp, xdmf_path)


def _parse_dims(text: str | None) -> tuple[int, ...] | None:
    if text is None:
        return None
    return tuple(int(x) for x in text.split())


def check_xdmf(xdmf_path: str | os.PathLike) -> list[str]:
    """Check an XDMF file against the HDF5 data it references.

    For every DataItem in HDF format: the file and dataset exist, the stated
    Dimensions equal the dataset's shape and NumberType/Precision its dtype.
    For every HyperSlab: start/stride/count have the source's rank and stay
    inside it, and the count matches the slab's Dimensions.  Also: triangle
    topologies hold NumberOfElements x 3 indices, XYZ geometries have 3
    columns, node attributes one value per geometry point, and times
    increase within each collection.  Returns the problems found (an empty
    list means valid).
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
        if item.get("ItemType") == "HyperSlab":
            children = item.findall("DataItem")
            if len(children) != 2:
                problems.append(f"HyperSlab needs 2 DataItems, has {len(children)}")
                return dims
            src_shape = item_shape(children[1])
            try:
                sel = np.array((children[0].text or "").split(), dtype=np.int64)
            except ValueError:
                problems.append("HyperSlab start/stride/count is not integers")
                return dims
            if src_shape is None:
                return dims
            r = len(src_shape)
            if sel.size != 3 * r:
                problems.append(f"HyperSlab selection has {sel.size} values, expected 3 x {r}")
                return dims
            start, stride, count = sel.reshape(3, r)
            last = start + (count - 1) * stride
            if (start < 0).any() or (stride < 1).any() or (count < 1).any() \
                    or (last >= np.array(src_shape)).any():
                problems.append(f"HyperSlab start {start.tolist()} stride {stride.tolist()} count "
                                f"{count.tolist()} leaves {children[1].text.strip()} of shape {src_shape}")
            elif [c for c in count if c != 1] != [d for d in dims if d != 1]:
                problems.append(f"HyperSlab count {count.tolist()} does not give Dimensions {dims}")
            return dims
        if item.get("Format", "XML") == "HDF":
            ds = dataset(item.text or "")
            if ds is None:
                return dims
            if tuple(ds.shape) != dims:
                problems.append(f"{item.text.strip()}: Dimensions {dims} but dataset shape {ds.shape}")
            key = (item.get("NumberType", "Float"), int(item.get("Precision", "4")))
            want = _NUMBER_TYPES.get(key)
            if want is None or np.dtype(want) != ds.dtype.newbyteorder("="):
                problems.append(f"{item.text.strip()}: NumberType/Precision {key} but dtype {ds.dtype}")
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
            n_points = None
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
                if shape is not None and topo.get("TopologyType") == "Triangle" and (
                        len(shape) != 2 or shape[1] != 3 or (n_el is not None and int(n_el) != shape[0])):
                    problems.append(f"grid {name}: Triangle topology of shape {shape}, "
                                    f"NumberOfElements {n_el}")
            for attr in g.findall("Attribute"):
                item = attr.find("DataItem")
                shape = item_shape(item) if item is not None else None
                if shape is not None and attr.get("Center") == "Node" and n_points is not None \
                        and shape[0] != n_points:
                    problems.append(f"grid {name}: node attribute {attr.get('Name')} has "
                                    f"{shape[0]} values for {n_points} points")
    finally:
        for f in files.values():
            if f is not None:
                f.close()
    # one message per distinct problem: a bad shared dataset repeats per frame
    return list(dict.fromkeys(problems))
