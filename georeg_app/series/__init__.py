"""``georeg track``: a displacement field per deformed stereo pair, serially or on Dask, and its output files."""
