"""The integrators: linearised backward Euler (implicit.py) with its kernels and matrix-free PCG, its two-level
coarse space, the explicit kernels, and the plain-NumPy oracle of a step."""
