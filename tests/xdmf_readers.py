"""Read an XDMF sidecar with real readers and save what each one sees.

    python tests/xdmf_readers.py RESULT.xdmf OUT.npz

Run as a child process by test_xdmf_readers.py, so ParaView's VTK (which
links its own MPI) never loads into the MPI test run.  Readers: ParaView's
vtkXdmf3Reader (behind its Xdmf3ReaderS/T), the legacy vtkXdmfReader (its
XDMFReader), both also through the ParaView proxies the README names
(paraview.simple's Xdmf3ReaderT and XDMFReader, as in pvpython and the GUI),
and meshio's TimeSeriesReader.  Keys of OUT.npz:
``<reader>/times`` and ``<reader>/<k>/<block>/<points|cells|point:NAME|cell:NAME>``
for time step k and block b in document order (meshio: the cloth only, its
points from the ``position`` attribute).  Exit status 3 when a reader's
package cannot be imported (the message names it).
"""
from __future__ import annotations

import os
import sys

import numpy as np


def _blocks(data):
    """The leaf datasets of a reader's output, in document order."""
    if data.IsA("vtkMultiPieceDataSet"):
        return [p for i in range(data.GetNumberOfPieces())
                if (p := data.GetPiece(i)) is not None]
    if data.IsA("vtkMultiBlockDataSet"):
        out = []
        for i in range(data.GetNumberOfBlocks()):
            block = data.GetBlock(i)
            if block is not None:
                out += _blocks(block)
        return out
    return [data]


def _vtk_to_numpy(array):
    from vtkmodules.util import numpy_support
    # a copy: the view would dangle once the reader moves to the next step
    return np.array(numpy_support.vtk_to_numpy(array))


def read_vtk(reader_class, path, out, key):
    from vtkmodules.vtkCommonExecutionModel import vtkStreamingDemandDrivenPipeline as SDDP

    reader = reader_class()
    reader.SetFileName(os.path.abspath(path))   # Xdmf3 resolves a bare name wrongly
    reader.UpdateInformation()
    times = np.array(reader.GetOutputInformation(0).Get(SDDP.TIME_STEPS()) or ())
    out[f"{key}/times"] = times
    for k, t in enumerate(times):
        reader.UpdateTimeStep(t)
        _save_blocks(reader.GetOutputDataObject(0), out, f"{key}/{k}")


def read_paraview(proxy, path, out, key):
    """Through ParaView's own reader proxies, as its GUI and pvpython use them."""
    from paraview import servermanager, simple

    reader = (simple.XDMFReader(FileNames=[os.path.abspath(path)]) if proxy == "XDMFReader"
              else getattr(simple, proxy)(FileName=[os.path.abspath(path)]))
    reader.UpdatePipelineInformation()
    times = np.array(reader.TimestepValues)
    out[f"{key}/times"] = times
    for k, t in enumerate(times):
        reader.UpdatePipeline(t)
        _save_blocks(servermanager.Fetch(reader), out, f"{key}/{k}")
    simple.Delete(reader)


def _save_blocks(data, out, prefix):
    """Points, triangles and arrays of every leaf block, under prefix/<block>."""
    for b, ds in enumerate(_blocks(data)):
        pre = f"{prefix}/{b}"
        pts = ds.GetPoints()
        out[f"{pre}/points"] = (_vtk_to_numpy(pts.GetData()) if pts is not None
                                else np.zeros((0, 3)))
        cells = ds.GetCells()
        types = _vtk_to_numpy(ds.GetCellTypesArray()) if ds.GetNumberOfCells() else np.zeros(0)
        if not np.all(types == 5):           # VTK_TRIANGLE
            raise SystemExit(f"{pre}: cells other than triangles")
        out[f"{pre}/cells"] = _vtk_to_numpy(cells.GetConnectivityArray()).reshape(-1, 3)
        for kind, arrays in (("point", ds.GetPointData()), ("cell", ds.GetCellData())):
            for i in range(arrays.GetNumberOfArrays()):
                out[f"{pre}/{kind}:{arrays.GetArrayName(i)}"] = _vtk_to_numpy(arrays.GetArray(i))


def read_meshio(path, out, key="meshio"):
    import meshio

    with meshio.xdmf.TimeSeriesReader(path) as reader:
        _, cells = reader.read_points_cells()
        times = []
        for k in range(reader.num_steps):
            t, point_data, cell_data = reader.read_data(k)
            times.append(t)
            pre = f"{key}/{k}/0"
            out[f"{pre}/points"] = point_data["position"]
            out[f"{pre}/cells"] = np.concatenate([c.data for c in cells if c.type == "triangle"])
            for name, value in point_data.items():
                out[f"{pre}/point:{name}"] = value
            for name, value in cell_data.items():
                out[f"{pre}/cell:{name}"] = np.concatenate(value)
        out[f"{key}/times"] = np.array(times)


def main(path, npz):
    out: dict[str, np.ndarray] = {}
    try:
        from vtkmodules.vtkIOXdmf2 import vtkXdmfReader
        from vtkmodules.vtkIOXdmf3 import vtkXdmf3Reader
        import meshio  # noqa: F401 - only to report a missing package here
        import paraview.simple  # noqa: F401
    except ImportError as err:
        print(f"cannot import a reader: {err} (Debian's python3-paraview and pip's meshio; "
              "scripts/setup.sh installs both)", file=sys.stderr)
        return 3
    read_vtk(vtkXdmf3Reader, path, out, "xdmf3")
    read_vtk(vtkXdmfReader, path, out, "legacy")
    read_paraview("Xdmf3ReaderT", path, out, "paraview_xdmf3t")
    read_paraview("XDMFReader", path, out, "paraview_xdmf")
    read_meshio(path, out)
    np.savez(npz, **out)
    return 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:]))
