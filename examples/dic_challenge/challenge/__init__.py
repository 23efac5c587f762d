"""The Stereo DIC Challenge example: configuration, nominal faces, visibility, measurement,
figures of merit and report (used by ``run.py``; see README "Real images")."""
