"""``georeg measure`` and ``georeg compare``: the methods of a run, the run and its output files."""
