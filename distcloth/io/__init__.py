"""Output: the run's HDF5 result file, its XDMF sidecar, previews, read-back.

:class:`ResultWriter` is collective under MPI (see :mod:`distcloth.io.h5writer`
for the protocol); it takes the communicator wrapper of
``distcloth/parallel/comm.py`` from the caller and never imports mpi4py itself.
"""
from distcloth.io.h5read import read_attrs, read_colliders, read_result
from distcloth.io.h5writer import CollectiveError, ResultWriter, ResumeRefused
from distcloth.io.xdmf import XdmfAttribute, XdmfBody, XdmfSeries, check_xdmf, write_xdmf

__all__ = ["ResultWriter", "CollectiveError", "ResumeRefused", "read_result", "read_attrs", "read_colliders",
           "write_xdmf", "check_xdmf", "XdmfAttribute", "XdmfBody", "XdmfSeries",
           "write_previews"]


def write_previews(h5_path, **kwargs):
    """See :func:`distcloth.io.preview.write_previews`."""
    # matplotlib takes a second to import: only callers that draw pay for it
    from distcloth.io.preview import write_previews as _write
    return _write(h5_path, **kwargs)
