"""3-D displacements of the measured surface from a series of stereo pairs, and their surface strains."""
