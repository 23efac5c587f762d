"""The linear solve of a Gauss-Newton step (the one extension point), the damped Gauss-Newton loop and Tikhonov (Eq. 10)."""
