"""Images of Eq. 3: the image model (prefilter + B-spline interpolant), its gradient, pyramids and the images' noise."""
