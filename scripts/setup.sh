#!/usr/bin/env bash
# Idempotent setup: Debian packages + the distcloth package in a venv with system site packages.
# python3-paraview (ParaView 5.11's Python modules: the Xdmf3 and legacy XDMF
# readers; Debian's python3-vtk9 has neither) and meshio (PyPI, with Debian's
# rich) are there for the test that opens results with real readers.
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
PKGS="openssh-client openmpi-bin libopenmpi-dev libmetis-dev libmetis5 petsc-dev python3-petsc4py python3-mpi4py python3-h5py-mpi python3-numpy python3-scipy python3-yaml python3-numba python3-pytest python3-matplotlib python3-gmsh python3-venv python3-pip python3-setuptools python3-paraview python3-rich"
missing=""
for p in $PKGS; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing="$missing $p"
done
if [ -n "$missing" ]; then
  echo "setup: installing Debian packages:$missing" >&2
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends $missing >/dev/null
fi
venv="$here/.venv"
if [ ! -x "$venv/bin/python" ]; then
  /usr/bin/python3 -m venv --system-site-packages "$venv"
fi
if ! "$venv/bin/python" -c "import distcloth" 2>/dev/null || [ "$here/pyproject.toml" -nt "$venv/.installed" ]; then
  "$venv/bin/python" -m pip install -q --no-build-isolation --no-deps -e "$here" >/dev/null
  touch "$venv/.installed"
fi
if ! "$venv/bin/python" -c "import meshio" 2>/dev/null; then
  "$venv/bin/python" -m pip install -q --no-deps "meshio==5.3.5" >/dev/null
fi
