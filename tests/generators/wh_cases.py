"""A Wiener-Hammerstein circuit as a test measures it, made without nlsid's simulator: two analog
filters around a diode-resistor saturation, like the SYSID 2009 benchmark (Schoukens, Suykens and
Ljung 2009: a third-order Chebyshev type I filter, 0.5 dB ripple, 4.4 kHz; a third-order inverse
Chebyshev filter, 40 dB stop band from 5 kHz; fs 51.2 kHz; a filtered Gaussian input).

The analog filters run at OVERSAMPLE times the sample rate, each by the exact zero-order-hold
equivalent at that rate (scipy's ``cont2discrete``) on the DAC's held input; the diode acts on the
finely sampled signal between them, and the ADC takes every OVERSAMPLE-th value. nlsid's models
run one step per sample, so a model fitted to these data is an approximation, as on a real circuit.

The diode-resistor: f(x) = x - C S softplus((x - T) / S), unit slope below the threshold T,
slope 1 - C above it (the resistor divides once the diode conducts), a knee of width S: asymmetric
and saturating.

:func:`sampled_circuit` is the same circuit in discrete time, exactly: each filter's zero-order
hold equivalent at FS, the diode on the samples between them (a smooth curve that neither a
polynomial nor a piecewise-linear one reproduces exactly).
"""

from __future__ import annotations

import numpy as np
from scipy.signal import butter, cheby1, cheby2, cont2discrete, lfilter

FS = 51200.0
OVERSAMPLE = 8
T, S, C = 0.25, 0.04, 0.8
FIRST = cheby1(3, 0.5, 2 * np.pi * 4400, analog=True)
SECOND = cheby2(3, 40, 2 * np.pi * 5000, analog=True)


def diode(x: np.ndarray, knee: float = S) -> np.ndarray:
    return x - C * knee * np.logaddexp(0.0, (x - T) / knee)


def held(tf, x: np.ndarray, rate: float) -> np.ndarray:
    """The analog filter ``tf`` on x held over each sample at ``rate``, exactly, from rest."""
    bd, ad, _ = cont2discrete(tf, 1.0 / rate, method="zoh")
    return lfilter(np.ravel(bd), np.ravel(ad), x)


def circuit(u: np.ndarray) -> np.ndarray:
    """The noise-free output sampled at FS for the held input u, from rest."""
    x = held(FIRST, np.repeat(u, OVERSAMPLE), FS * OVERSAMPLE)
    return held(SECOND, diode(x), FS * OVERSAMPLE)[::OVERSAMPLE]


def sampled_circuit(u: np.ndarray, knee: float) -> np.ndarray:
    """The discrete-time circuit (module docstring) with a diode knee of width ``knee``."""
    return held(SECOND, diode(held(FIRST, u, FS), knee), FS)


def excitation(n: int, rng: np.random.Generator, rms: float = 0.68) -> np.ndarray:
    """Gaussian noise low-passed at 8.5 kHz (a tenth-order Butterworth), scaled to ``rms``."""
    u = lfilter(*butter(10, 8500 / (FS / 2)), rng.standard_normal(n))
    return u * rms / np.std(u)
