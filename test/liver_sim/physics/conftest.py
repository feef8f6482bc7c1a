"""Fixtures shared by the physics tests (helpers live in test/support)."""
import pytest

from liver_sim.mesh.liver_shape import default_liver

from meshes import box_mesh


@pytest.fixture(scope="module")
def box():
    """An 8 × 6 × 6 cm box of 2 cm cubes (432 tets): a small liver stand-in."""
    return box_mesh(4, 3, 3, 0.02)


@pytest.fixture(scope="module")
def liver():
    """The default liver (liver_sim.mesh.liver_shape.default_liver, ~1.2k tets)."""
    return default_liver()
