"""Files in and out: recordings (HDF5, MCAP), configs and their validation, provenance."""
