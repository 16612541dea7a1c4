"""Full random orthogonal multisines: n_u inputs, n_u experiments per realization (book (6-118)).

To separate the n_y x n_u frequency response matrix G(k) from the outputs, n_u experiments with
linearly independent input vectors are needed at every line (book Section 3.8, Eq. (3-31); (6-116)).
Column e of the n_u x n_u matrix U(k) holds the input spectra of experiment e; the book's design
(6-118), with Lambda_k the identity up to one amplitude per input, is

    U(k) = diag(U_r(k)) T diag(exp(j phi_e(k))),

- ``U_r(k) = |U_r| exp(j theta_r(k))``: a random-phase multisine per input r, flat amplitudes;
- ``T``: a unitary matrix (T^H = T^-1), the normalised Hadamard matrix where n_u is a power of two
  (Guillaume et al. 1997; Ex. 53 uses [u, u; u, -u]), else the DFT matrix
  ``T[r, e] = exp(-2 pi j r e / n_u) / sqrt(n_u)`` (Dobrowiecki, Schoukens and Guillaume 2006);
- ``phi_e(k)``: independent uniform phases per experiment and line, so that two columns of U(k)
  are uncorrelated and the stochastic nonlinear distortions are uncorrelated over the experiments
  (book, Project 4 after (6-118)).

Every entry of T has modulus 1/sqrt(n_u); here T is scaled by sqrt(n_u) so that every input of
every experiment is a multisine with the requested rms (the book's T leaves 1/sqrt(n_u) of it).
The scaling does not change the conditioning: U(k) U(k)^H = n_u diag(|U_r(k)|^2), so
``U(k)^-1 = U(k)^H diag(1/|U_r(k)|^2) / n_u`` and the FRM noise is the same at every entry of a
column (:mod:`nlsid.analysis.frm`).

Spectra follow nlsid's DFT scaling (:mod:`nlsid.analysis.lines`): ``U(k) = (1/N) sum_n u(n)
exp(-j 2 pi k n / N)``, so a flat multisine of rms ``s`` on F lines has ``|U_r(k)| = s / sqrt(2 F)``.
The time signals are the inverse real FFT of these spectra: real, periodic in N samples, with
energy at the excited bins only (DC and Nyquist are never excited).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from nlsid.errors import InputError
from nlsid.signals.multisine import random_phases

TRANSFORMS = ("auto", "hadamard", "dft")


def is_power_of_two(n: int) -> bool:
    """True for 1, 2, 4, 8, ..."""
    return n >= 1 and n & (n - 1) == 0


def orthogonal_transform(n_inputs: int, kind: str = "auto") -> np.ndarray:
    """The unitary n_u x n_u matrix T of (6-118).

    Parameters
    ----------
    n_inputs : int
        n_u >= 1.
    kind : {"auto", "hadamard", "dft"}
        ``hadamard``: Sylvester's Hadamard matrix over sqrt(n_u) (n_u a power of two);
        ``dft``: ``T[r, e] = exp(-2 pi j r e / n_u) / sqrt(n_u)``; ``auto``: Hadamard where n_u is a
        power of two, else DFT.

    Returns
    -------
    numpy.ndarray
        T with ``T^H T = I`` and ``|T[r, e]| = 1/sqrt(n_u)`` for every entry.

    Examples
    --------
    >>> orthogonal_transform(2) * np.sqrt(2)
    array([[ 1.,  1.],
           [ 1., -1.]])
    """
    if not isinstance(n_inputs, (int, np.integer)) or n_inputs < 1:
        raise InputError("n_inputs", f"expected an integer >= 1, got {n_inputs!r}")
    if kind not in TRANSFORMS:
        raise InputError("transform", f"expected one of {', '.join(TRANSFORMS)}, got {kind!r}")
    if kind == "hadamard" and not is_power_of_two(n_inputs):
        raise InputError("transform", f"a Hadamard matrix needs a power of two inputs, got {n_inputs}; use 'dft'")
    if kind == "hadamard" or (kind == "auto" and is_power_of_two(n_inputs)):
        return scipy.linalg.hadamard(n_inputs).astype(float) / np.sqrt(n_inputs)
    r = np.arange(n_inputs)
    return np.exp(-2j * np.pi * np.outer(r, r) / n_inputs) / np.sqrt(n_inputs)


@dataclass
class OrthogonalMultisine:
    """One realization of a full random orthogonal multisine (book (6-118)).

    Attributes
    ----------
    period : int
        N, samples per period.
    bins : numpy.ndarray
        The F excited bins (line k is the frequency k fs / N).
    transform : numpy.ndarray
        The unitary n_u x n_u matrix T.
    spectra : numpy.ndarray
        U(k), shape (F, n_u, n_u): ``spectra[f, r, e]`` is input r of experiment e at ``bins[f]``,
        with nlsid's 1/N DFT scaling.
    input_phases, experiment_phases : numpy.ndarray
        theta_r(k), shape (n_u, F), and phi_e(k), shape (n_u, F), in radians.
    """

    period: int
    bins: np.ndarray
    transform: np.ndarray
    spectra: np.ndarray
    input_phases: np.ndarray
    experiment_phases: np.ndarray

    @property
    def n_inputs(self) -> int:
        return self.spectra.shape[1]

    @property
    def n_experiments(self) -> int:
        return self.spectra.shape[2]

    def signals(self) -> np.ndarray:
        """One period of every input of every experiment, shape (n_u experiments, n_u inputs, N).

        ``u_r^[e](n) = sum_k 2 Re(U[r, e](k) exp(j 2 pi k n / N))``, by inverse real FFT: real, exact
        to rounding, its DFT (1/N scaling) equal to :attr:`spectra` at :attr:`bins` and 0 elsewhere.
        """
        full = np.zeros((self.n_experiments, self.n_inputs, self.period // 2 + 1), dtype=complex)
        full[..., self.bins] = self.period * np.transpose(self.spectra, (2, 1, 0))
        return np.fft.irfft(full, self.period, axis=-1)


def check_bins(period: int, bins) -> np.ndarray:
    """The excited bins as sorted unique integers in 1 .. ceil(N/2) - 1, or an InputError naming ``bins``."""
    if not isinstance(period, (int, np.integer)) or period < 3:
        raise InputError("period", f"expected an integer number of samples >= 3, got {period!r}")
    array = np.asarray(bins)
    if array.ndim != 1 or array.size == 0 or not np.issubdtype(array.dtype, np.integer):
        raise InputError("bins", "expected a non-empty 1-D array of integer bin indices")
    highest = (period - 1) // 2
    if array.min() < 1 or array.max() > highest:
        raise InputError("bins", f"expected bins in 1 .. {highest} (no DC, no Nyquist) for a period of {period}, "
                                 f"got {array.min()} .. {array.max()}")
    if np.unique(array).size != array.size:
        raise InputError("bins", "expected each bin once")
    return np.sort(array).astype(np.int64)


def orthogonal_multisine(period: int, bins, n_inputs: int, rms=1.0, transform: str = "auto",
                         rng: np.random.Generator | int | None = None) -> OrthogonalMultisine:
    """One realization of full random orthogonal multisines for ``n_inputs`` inputs (book (6-118)).

    ``U(k) = diag(|U_r| exp(j theta_r(k))) sqrt(n_u) T diag(exp(j phi_e(k)))`` at every excited bin,
    with ``|U_r| = rms_r / sqrt(2 F)`` (flat amplitudes), theta and phi independent and uniform on
    [0, 2 pi). Draw M realizations by calling it M times with one generator.

    Parameters
    ----------
    period : int
        N, samples per period.
    bins : array of int
        Excited bins, 1 <= k < N/2.
    n_inputs : int
        n_u; the design has n_u experiments.
    rms : float or sequence of float
        The rms of each input in each experiment (one value for all inputs, or one per input).
    transform : {"auto", "hadamard", "dft"}
        The unitary matrix T (:func:`orthogonal_transform`).
    rng : numpy.random.Generator or int, optional
        Source of the phases (an int is a seed): the same seed gives the same signals.

    Returns
    -------
    OrthogonalMultisine

    Examples
    --------
    >>> design = orthogonal_multisine(64, np.arange(1, 20, 2), 2, rms=0.5, rng=1)
    >>> u = design.signals()
    >>> u.shape, np.allclose(np.sqrt(np.mean(u**2, axis=-1)), 0.5)
    ((2, 2, 64), True)
    """
    bins = check_bins(period, bins)
    T = orthogonal_transform(n_inputs, transform)
    levels = np.broadcast_to(np.asarray(rms, dtype=float), (n_inputs,)) if np.ndim(rms) == 0 else np.asarray(rms, float)
    if levels.shape != (n_inputs,) or not np.all(np.isfinite(levels)) or np.any(levels <= 0):
        raise InputError("rms", f"expected a positive rms, or {n_inputs} positive values (one per input)")
    generator = np.random.default_rng(rng)
    n_lines = bins.size
    theta = np.stack([random_phases(n_lines, generator) for _ in range(n_inputs)])
    phi = np.stack([random_phases(n_lines, generator) for _ in range(n_inputs)])
    magnitude = levels / np.sqrt(2.0 * n_lines)                               # |U_r|, (n_u,)
    inputs = magnitude[None, :, None] * np.exp(1j * theta.T)[:, :, None]      # diag(U_r(k)): (F, n_u, 1)
    spectra = inputs * (np.sqrt(n_inputs) * T)[None] * np.exp(1j * phi.T)[:, None, :]
    return OrthogonalMultisine(period=int(period), bins=bins, transform=T, spectra=spectra,
                               input_phases=theta, experiment_phases=phi)
