#!/usr/bin/env bash
# The fabric lab on every preset, 2 ranks, reports in docs/lab/: each preset
# as it is (bending_model null: grid_lines on the grid specimens) on standard specimens,
# its bending tests again with the shell model, and the drape test on the
# standard specimen (3,449 vertices: 10-20 s a fabric).
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
cd "$here"
mkdir -p docs/lab
presets=${*:-"cotton wool denim silk polyester_knit"}
for p in $presets; do
  scripts/mpiexec.sh 2 .venv/bin/distcloth lab "$p" --tests tensile shear bending peirce \
    --output "docs/lab/$p.md"
  scripts/mpiexec.sh 2 .venv/bin/distcloth lab "$p" --set bending_model=dihedral_shell \
    --tests bending peirce --output "docs/lab/${p}_shell.md"
  scripts/mpiexec.sh 2 .venv/bin/distcloth lab "$p" --tests cusick \
    --output "docs/lab/${p}_drape.md"
done
