"""The shape measurement: Eqs. 7-8 at fixed cameras, calibration (Eq. 6), the gauge, the multiscale fixed point and its uncertainty."""
