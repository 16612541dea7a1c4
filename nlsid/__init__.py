"""nlsid: nonlinear system identification from measured data.

The library is usable without the command line: ``nlsid.io`` reads and writes recordings and
configs, ``nlsid.signals`` designs excitations, and the analysis packages work on numpy arrays.
"""

__version__ = "0.1.0"
