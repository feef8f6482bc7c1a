"""A slab pressed by a tool with one short explicit step per frame, where Eq. 3's forces are read before the nodes
have moved noticeably (test/liver_sim/physics/contact: the contact kernels and the local model)."""
from liver_sim.physics.model import LiverModel
from liver_sim.physics.settings import ModelParams
from liver_sim.physics.tools.tool import Tool

from meshes import box_mesh

#: The penalty λ (N/m), the depth the tests press (m) and the slab's grid spacing (m).
STIFFNESS = 250.0
DEPTH = 0.002
SPACING = 0.02


def slab_mesh():
    """A 10 × 10 × 4 cm slab; its top face is z = 0.04 m, with a grid vertex at (0.04, 0.04)."""
    return box_mesh(5, 5, 2, SPACING)


def one_step_model(mesh, tool):
    """One 10 µs explicit step per frame: forces are read before the nodes have moved noticeably (the
    implicit step's contacts, evaluated at the end of its step: test/liver_sim/physics/solver/test_implicit.py)."""
    params = ModelParams(integrator="symplectic_euler", substeps=1, frame_rate_hz=1e5,
                         contact_stiffness_n_per_m=STIFFNESS,
                         contact_damping_ns_per_m=0.0)
    return LiverModel(mesh, params, Tool(tool))
