"""The Stereo DIC Challenge example: configuration (specimen, analysis regions), figures of
merit, comparison with the laser and pyvale, figures and report (used by ``analyse_part.py``;
see README "Real images")."""
