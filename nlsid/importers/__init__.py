"""Importers of foreign files (CSV/TSV, MATLAB .mat, plain HDF5, foreign MCAP) into the recording format.

:func:`nlsid.importers.convert.import_file` reads the selected signals, infers the excitation
(:mod:`nlsid.signals.inference`) and cuts the runs; ``nlsid import`` writes them.
"""
