"""What a run measures: the nominal model of each geometry kind and the cameras."""
