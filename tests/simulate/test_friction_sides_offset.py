"""Coulomb friction that differs by direction is symmetric friction with a constant force: with a
constant force f0 on the mass, m v' = gain u + f0 - fc sign(v) - ... slides against fc - f0 for
v > 0 and fc + f0 for v < 0 and sticks while gain u - k p lies in [-(fc + f0), fc - f0], which is
the law with fc_pos = fc - f0, fc_neg = fc + f0 (docs/configs.md). So the two are one model, and a
diagnosis, which fits a force offset as a nuisance, cannot name the asymmetry from data
(docs/commands.md, diagnose). Asserted: the two configs simulate the same record to rounding,
and the opposite offset does not.
"""

from __future__ import annotations

import numpy as np

from nlsid.io import model_config as mc
from nlsid.io.run import Run
from nlsid.models import from_config
from nlsid.simulate.runs import simulate_run

FS = 1000.0
BASE = {"type": "mass_spring_damper", "mass": 1.0, "damping": 20.0, "stiffness": 4e4, "gain": 1e4}


def simulate(model: dict, u: np.ndarray) -> np.ndarray:
    cfg = mc.SimulateConfig.model_validate({"model": model})
    return simulate_run(from_config.model(cfg), None, Run("r", FS, "arbitrary", u), None).y


def test_sided_coulomb_is_symmetric_coulomb_with_a_constant_force():
    t = np.arange(3000) / FS
    u = 0.05 * np.sin(2 * np.pi * 3 * t) + 0.01 * np.sin(2 * np.pi * 17 * t)  # sticks at each reversal
    sided = simulate({**BASE, "nonlinearities": [{"type": "coulomb", "fc_pos": 140.0, "fc_neg": 160.0}]}, u)
    offset = simulate({**BASE, "force_offset": 10.0, "nonlinearities": [{"type": "coulomb", "fc": 150.0}]}, u)
    wrong = simulate({**BASE, "force_offset": -10.0, "nonlinearities": [{"type": "coulomb", "fc": 150.0}]}, u)
    scale = np.max(np.abs(sided))
    assert np.max(np.abs(sided - offset)) < 1e-12 * scale
    assert np.max(np.abs(sided - wrong)) > 1e-2 * scale
