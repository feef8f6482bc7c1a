"""A tiny scene for the implicit step's kernels and solver: a small box perturbed and moving, one node held, a
1-node and a 3-node contact (test/liver_sim/physics/solver)."""
import numpy as np

from liver_sim.physics.contact.rows import Contacts
from liver_sim.physics.settings import ModelParams
from liver_sim.physics.tissue.springs import build_springs

from meshes import box_mesh


def tiny_scene(offset_m=0.002, speed_m_s=0.05):
    """A 2×1×1 box of 12 tets, perturbed and moving, node 0 held, a 1-node and a 3-node contact."""
    mesh = box_mesh(2, 1, 1, 0.02)
    springs = build_springs(mesh, ModelParams())
    rng = np.random.default_rng(3)
    x = mesh.points + rng.normal(scale=offset_m, size=mesh.points.shape)
    v = rng.normal(scale=speed_m_s, size=x.shape)
    inv_mass = 1.0 / mesh.lumped_masses(1060.0)
    inv_mass[0] = 0.0
    v[0] = 0.0
    top = np.flatnonzero(mesh.points[:, 2] > 0.019)
    normal = np.array([[0.0, 0.0, -1.0], [0.1, 0.0, -1.0] / np.linalg.norm([0.1, 0.0, -1.0])])
    nodes = np.array([[top[0], -1, -1], top[1:4]])
    weights = np.array([[1.0, 0.0, 0.0], [0.2, 0.5, 0.3]])
    offset = np.array([normal[e] @ (weights[e][n >= 0] @ x[n[n >= 0]]) + 0.001  # 1 mm deep
                       for e, n in enumerate(nodes)])
    contacts = Contacts(nodes, weights, normal, offset, np.array([0.01, -0.02]), np.array([300.0, 200.0]),
                        np.array([1.0, 0.5]))
    external = rng.normal(scale=0.01, size=x.shape)
    return mesh, springs, x, v, inv_mass, contacts, external
