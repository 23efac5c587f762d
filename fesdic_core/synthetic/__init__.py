"""Synthetic scaffolding: a stereo renderer with a known surface and accuracy against that truth."""
