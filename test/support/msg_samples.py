"""Sample inputs the message tests share: normals along the axes and off them, random skins."""
import numpy as np

#: Normals along each axis, both ways, and one off the axes (not of unit length).
AXES = [(0, 0, 1), (0, 0, -1), (1, 0, 0), (-1, 0, 0), (0, 1, 0), (0.3, -0.2, -0.9)]


def random_skin(rng: np.random.Generator, n_points: int, n_triangles: int) -> np.ndarray:
    """(n_triangles, 3) node indices drawn from [0, n_points) by `rng`: triangles of a skin (not a closed surface)."""
    return rng.integers(0, n_points, size=(n_triangles, 3))
