"""A sewn garment comes to rest on a resting body: the bundled skirt, its
kinetic energy and strain 0.3 s after the weld (docs/integrators.md,
"Where contacts stop the cloth")."""
from __future__ import annotations

import h5py
import numpy as np
import yaml

from conftest import ROOT
from distcloth.config.load import config_from_dict
from distcloth.parallel.comm import Comm
from distcloth.run import run


def test_the_sewn_skirt_settles_on_the_body(shared_tmp, comm):
    # configs/skirt_on_body.yaml welded at 0.5 s and run to 0.8 s on 2 ranks.
    # Measured: kinetic energy 1.6e-5 J at the end, largest strain 4.3-4.4 %
    # from 0.6 s (the draped skirt's 4.2 %, docs/garments.md).  Linearised at
    # the predictor the skirt kept jittering: 5e-4 J at the end, 9 % strain
    # at 0.64 s.  The bounds sit between: 1e-4 J, 6 %.
    with open(ROOT / "configs/skirt_on_body.yaml") as fh:
        raw = yaml.safe_load(fh)
    raw["time"]["end"] = 0.8
    raw["output"] = {"file": str(shared_tmp / "skirt.h5"), "every": 0.05, "preview": False}
    cfg = config_from_dict(raw, str(ROOT / "configs"), "skirt.yaml")
    assert cfg.time.linearise_at == "start"
    assert run(cfg, Comm(comm), quiet=True, progress=False) == 0
    with h5py.File(shared_tmp / "skirt.h5", "r") as f:
        assert f.attrs["status"] == "completed"
        d = f["diagnostics"]
        t, ke, strain = d["time"][:], d["kinetic_energy"][:], d["max_strain"][:]
    assert ke[-1] < 1e-4, ke[-1]
    assert strain[t >= 0.6].max() < 0.06, strain[t >= 0.6].max()
    assert np.isfinite(ke).all()
