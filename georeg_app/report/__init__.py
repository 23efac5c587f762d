"""Figures and the self-contained HTML reports of a run and of a series."""
