#!/usr/bin/env bash
# Idempotent setup: Debian packages + the distcloth package in a venv with system site
# packages, then numba's kernels compiled once.  libjs-three is the 3D library
# `distcloth view` copies into its pages; chromium runs the viewer's test.
# python3-paraview (ParaView 5.11's Python modules: the Xdmf3 and legacy XDMF
# readers; Debian's python3-vtk9 has neither) and meshio (PyPI, with Debian's
# rich) are there for the test that opens results with real readers.
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
PKGS="openssh-client openmpi-bin libopenmpi-dev libmetis-dev libmetis5 petsc-dev python3-petsc4py python3-mpi4py python3-h5py-mpi python3-numpy python3-scipy python3-yaml python3-numba python3-pytest python3-matplotlib python3-gmsh libjs-three chromium python3-venv python3-pip python3-setuptools python3-paraview python3-rich"
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
# Byte code written here, once per changed module: where PYTHONDONTWRITEBYTECODE
# is set (containers often set it) Python still reads it but never writes it, and
# every process, every rank, would compile the package's modules again (0.3 s of
# a start).  Only a speed-up: a tree it cannot write to is no reason to stop.
"$venv/bin/python" -m compileall -q "$here/distcloth" >/dev/null || true

# numba compiles a kernel on its first call and caches it beside its source
# (cache=True): a tiny run of two scenes here (the README's hammock, and a
# tablecloth touching a sphere, with self-collisions, for the collision
# kernels) so that a first real
# run does not pay 1-2 minutes of compilation.  Redone when a file that uses
# numba changes; a failed warm-up only means the first run compiles.
warm="$venv/.numba-warm"
if [ ! -e "$warm" ] || [ -n "$(find "$here/distcloth" -name '*.py' -newer "$warm" -print0 \
                                | xargs -0 -r grep -l numba)" ]; then
  echo "setup: compiling the numba kernels (once, about a minute)" >&2
  tmp=$(mktemp -d)
  ok=1
  "$venv/bin/distcloth" run "$here/configs/default.yaml" --quiet --output "$tmp/a.h5" \
    --set time.end=0.03 --set output.preview=false >/dev/null 2>"$tmp/log" || ok=0
  "$venv/bin/distcloth" run "$here/configs/tablecloth_sphere.yaml" --quiet --output "$tmp/b.h5" \
    --set time.end=0.03 --set output.preview=false --set "cloth.0.mesh.center=[0,0,0.502]" \
    --set "cloth.0.mesh.grid.resolution=[9,9]" \
    --set "effects=[gravity,membrane,bending,damping,collisions,self_collision]" \
    >/dev/null 2>>"$tmp/log" || ok=0
  if [ $ok = 1 ]; then touch "$warm"; else
    echo "setup: the warm-up run failed (a first run will compile the kernels):" >&2
    tail -n 5 "$tmp/log" >&2
  fi
  rm -rf "$tmp"
fi
