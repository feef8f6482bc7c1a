"""Fixtures of the contact tests."""
import pytest
from contact_slab import slab_mesh


@pytest.fixture(scope="module")
def slab():
    """contact_slab.slab_mesh: 10 × 10 × 4 cm, top face z = 0.04 m."""
    return slab_mesh()
