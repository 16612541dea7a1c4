"""Full random orthogonal multisines (book (6-118)): every number checked against the definition.

The DFT of each time signal is taken here with numpy's FFT and the 1/N scaling of
nlsid.analysis.lines; "exact" means 1e-12 (FFT round-off is about 1e-15 relative).
"""

from __future__ import annotations

import numpy as np
import pytest

from nlsid.errors import InputError
from nlsid.signals.orthogonal_multisine import orthogonal_multisine, orthogonal_transform

N = 128
BINS = np.arange(3, 60, 2)


@pytest.mark.parametrize("n, kind", [(1, "auto"), (2, "hadamard"), (4, "hadamard"), (3, "dft"), (5, "dft"),
                                     (4, "dft")])
def test_transform_is_unitary_with_entries_of_equal_modulus(n, kind):
    T = orthogonal_transform(n, kind)
    assert np.allclose(T.conj().T @ T, np.eye(n), atol=1e-14)
    assert np.allclose(np.abs(T), 1 / np.sqrt(n), atol=1e-15)


def test_auto_is_hadamard_for_powers_of_two_and_dft_otherwise():
    assert np.array_equal(orthogonal_transform(2) * np.sqrt(2), [[1, 1], [1, -1]])  # Ex. 53: [u, u; u, -u]
    assert np.isrealobj(orthogonal_transform(4))
    w = np.exp(-2j * np.pi / 3)
    assert np.allclose(orthogonal_transform(3) * np.sqrt(3), [[1, 1, 1], [1, w, w**2], [1, w**2, w**4]], atol=1e-15)


@pytest.mark.parametrize("n_inputs", [1, 2, 3])
def test_signals_have_the_designed_spectrum_and_rms(n_inputs):
    rms = [0.5, 2.0, 1.2][:n_inputs]
    design = orthogonal_multisine(N, BINS, n_inputs, rms=rms, rng=7)
    u = design.signals()
    assert u.shape == (n_inputs, n_inputs, N) and np.isrealobj(u)
    spectrum = np.fft.rfft(u, axis=-1) / N                       # (experiment, input, line)
    assert np.allclose(spectrum[..., BINS], design.spectra.transpose(2, 1, 0), atol=1e-12)
    others = np.setdiff1d(np.arange(N // 2 + 1), BINS)
    assert np.max(np.abs(spectrum[..., others])) < 1e-12
    # every input of every experiment: |U(k)| = rms / sqrt(2 F), so rms^2 = sum 2 |U(k)|^2 (Parseval)
    assert np.allclose(np.abs(design.spectra), (np.array(rms) / np.sqrt(2 * BINS.size))[None, :, None], rtol=1e-12)
    assert np.allclose(np.sqrt(np.mean(u**2, axis=-1)), np.array(rms)[None, :], rtol=1e-12)


@pytest.mark.parametrize("n_inputs", [2, 3, 4])
def test_experiments_are_orthogonal_at_every_line(n_inputs):
    """U U^H = n_u diag(|U_r|^2): the columns (experiments) are orthogonal, so U is invertible."""
    design = orthogonal_multisine(N, BINS, n_inputs, rms=np.arange(1, n_inputs + 1), rng=3)
    U = design.spectra
    gram = U @ U.conj().transpose(0, 2, 1)
    expected = n_inputs * np.abs(U[:, :, :1]) ** 2 * np.eye(n_inputs)
    assert np.allclose(gram, expected, atol=1e-14)


def test_columns_are_uncorrelated_over_realizations():
    """E{U[r, e] conj(U[s, f])} = 0 for e != f (the hint of Project 4): the normalized sample
    correlation over 200 realizations x 29 lines (5800 products of unit modulus, each of mean 0 and
    variance 1) has std 1/sqrt(5800) = 0.013; 5 std = 0.066."""
    rng = np.random.default_rng(5)
    U = np.stack([orthogonal_multisine(N, BINS, 2, rng=rng).spectra for _ in range(200)])
    unit = U / np.abs(U)
    for r, s in [(0, 0), (0, 1), (1, 1)]:
        correlation = np.mean(unit[:, :, r, 0] * np.conj(unit[:, :, s, 1]))
        assert abs(correlation) < 0.066
    # the same input in the same experiment is fully correlated with itself (the test can tell)
    assert abs(np.mean(unit[:, :, 0, 0] * np.conj(unit[:, :, 0, 0]))) == pytest.approx(1.0)


def test_same_seed_same_signals_other_seed_other_phases():
    a = orthogonal_multisine(N, BINS, 3, rng=11).signals()
    assert np.array_equal(a, orthogonal_multisine(N, BINS, 3, rng=11).signals())
    assert not np.allclose(a, orthogonal_multisine(N, BINS, 3, rng=12).signals())


@pytest.mark.parametrize("kwargs, where", [
    (dict(bins=[0, 3]), "bins"), (dict(bins=[3, 64]), "bins"), (dict(bins=[3, 3]), "bins"),
    (dict(bins=[1.5]), "bins"), (dict(n_inputs=0), "n_inputs"), (dict(n_inputs=3, transform="hadamard"), "transform"),
    (dict(transform="walsh"), "transform"), (dict(rms=-1.0), "rms"), (dict(rms=[1.0, 2.0, 3.0]), "rms"),
    (dict(period=2), "period"),
])
def test_bad_arguments_name_the_argument(kwargs, where):
    arguments = dict(period=N, bins=BINS, n_inputs=2, rms=1.0, transform="auto", rng=0) | kwargs
    with pytest.raises(InputError) as error:
        orthogonal_multisine(**arguments)
    assert str(error.value).startswith(f"{where}:")
