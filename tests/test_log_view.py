"""``-log_view`` lists distcloth's step stages as PETSc log events, with
their call counts, beside PETSc's own events."""
from __future__ import annotations

import re

import pytest

from conftest import ROOT, run_cli


@pytest.mark.rank0_only
def test_log_view_lists_the_stages(tmp_path):
    res = run_cli(["run", ROOT / "configs" / "default.yaml", "--quiet",
                   "--set", "time.end=0.03", "--set", "cloth.0.mesh.grid.resolution=[9,9]",
                   "--set", "output.preview=false", "--output", tmp_path / "r.h5", "-log_view"],
                  ranks=2)
    assert res.returncode == 0, res.stderr
    events = res.stdout[res.stdout.index("Event                Count"):]
    assert re.search(r"^KSPSolve +\d+ ", events, re.M)
    # three steps: one solve each; two frames (the start and the last step)
    for name, calls in (("kinematics", 3), ("force:membrane", None), ("assembly", None),
                        ("solve", 3), ("update", 3), ("diagnostics", 3), ("output", 2)):
        found = re.search(rf"^{re.escape(name)} +(\d+) ", events, re.M)
        assert found, f"{name} not in -log_view:\n{events}"
        assert calls is None or int(found.group(1)) == calls, found.group(0)
    # the solve's parts and the health check have their own events
    for name in ("solve:filter", "solve:set_values", "solve:check", "health"):
        found = re.search(rf"^{re.escape(name)} +(\d+) ", events, re.M)
        assert found and int(found.group(1)) == 3, f"{name} not in -log_view:\n{events}"
    # a stage the scene does not have is no event with calls
    assert not re.search(r"^force:sewing +[1-9]", events, re.M)
