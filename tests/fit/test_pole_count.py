"""How many poles an FRF supports (nlsid.fit.pole_count.select_poles).

The structure is a modal superposition evaluated with numpy in this file, with circular complex
Gaussian noise of known variance on each line; at the right order the cost is (1/2) chi^2(2F - n_theta)
and stays below the bound with probability 0.99865, while an order that misses a mode leaves a cost
many times the bound.
"""

from __future__ import annotations

import numpy as np
import pytest

from nlsid.errors import InputError
from nlsid.fit.pole_count import select_poles
from nlsid.fit.frf_data import FRFData


def _structure_frf(modes: int, noise: float, seed: int) -> tuple[FRFData, np.ndarray]:
    rng = np.random.default_rng(seed)
    fs, period = 2000.0, 4096
    fn = np.geomspace(20.0, 600.0, modes)
    zeta = rng.uniform(0.01, 0.03, modes)
    wn = 2 * np.pi * fn
    poles = -zeta * wn + 1j * wn * np.sqrt(1 - zeta**2)
    residues = (1 + rng.uniform(size=modes) + 0.3j * rng.normal(size=modes)) * wn
    bins = np.arange(20, 1400)
    s = 2j * np.pi * bins * fs / period
    G = sum(r / (s - p) + np.conj(r) / (s - np.conj(p)) for p, r in zip(poles, residues)) + 0.2
    sd = noise * np.mean(np.abs(G)) * np.ones(bins.size)
    G = G + sd / np.sqrt(2) * (rng.normal(size=bins.size) + 1j * rng.normal(size=bins.size))
    return FRFData(bins, G, sd**2, fs, period), fn


def test_eight_modes_need_sixteen_poles():
    """8 well-separated modes with 1 % noise: 16 poles chosen, within the bound, stable; the orders
    visited (doubling 1, 2, 4, 8, 16, then bisection 12, 14, 15) below 16 each miss a mode and lie
    above their bound, 15 among them."""
    data, fn = _structure_frf(8, 0.01, seed=2)
    selection = select_poles(data, max_poles=20, domain="s")
    assert selection.accepted and selection.fit.order == 16 and selection.fit.stable()
    assert [c.poles for c in selection.scan] == [1, 2, 4, 8, 12, 14, 15, 16]
    assert all(not c.accepted for c in selection.scan[:-1])
    assert "(15 poles: above it)" in selection.reason
    found = [m["frequency"] for m in selection.fit.modes()]
    assert np.allclose(found, fn, rtol=0.01)


def test_no_order_within_bound_said():
    """Capped at 6 poles, 8 modes cannot fit: not accepted, the reason says so, a fit still returned."""
    data, _ = _structure_frf(8, 0.01, seed=2)
    selection = select_poles(data, max_poles=6, domain="s")
    assert not selection.accepted and "no order up to 6 poles" in selection.reason
    assert selection.fit.order <= 6 and [c.poles for c in selection.scan] == [1, 2, 4, 6]


def test_bad_max_poles_named():
    data, _ = _structure_frf(2, 0.01, seed=1)
    with pytest.raises(InputError) as error:
        select_poles(data, max_poles=0)
    assert str(error.value).startswith("max_poles")
