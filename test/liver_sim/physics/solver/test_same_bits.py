"""The same bits whatever the CPU numba compiles for (issue 45): a press on a liver large enough for the two-level
preconditioner, in this process (the host CPU) and in one whose kernels are compiled for a generic x86-64
(NUMBA_CPU_NAME=generic, a cache of its own), ends on the same positions and forces to the bit.  The child compiles
every kernel of a frame anew for that CPU: a few minutes of one core."""
import os
import platform
import subprocess
import sys

import numpy as np
import pytest

#: The press, run here and in the child: prints nothing, writes positions and forces of every frame to argv[1].
PRESS = """
import sys
import numpy as np
from liver_sim.mesh.landmarks import press_anchor
from liver_sim.mesh.liver_shape import build_liver
from liver_sim.physics.contact.tool_geometry import ToolPose
from liver_sim.physics.model import LiverModel
from liver_sim.physics.settings import ModelParams

def press(path):
    mesh = build_liver(2500)
    model = LiverModel(mesh, ModelParams(preconditioner="two_level", solver_threads="one"))
    anchor, radius = press_anchor(mesh), model.tool.shape.radius_m
    positions, forces = [], []
    for k in range(40):
        result = model.step_frame(ToolPose(anchor + [0.0, 0.0, radius - 0.008 * min(1.0, (k + 1) / 30)]))
        positions.append(model.state.positions.copy())
        forces.append(result.tool_forces_n[0])
    assert model.structure.step_solver.startswith("pcg two-level")
    np.savez(path, positions=np.array(positions), forces=np.array(forces))

if __name__ == "__main__":
    press(sys.argv[1])
"""


@pytest.mark.skipif(platform.machine() not in ("x86_64", "AMD64"), reason="a generic x86-64 target")
def test_a_press_gives_the_same_bits_compiled_for_the_host_and_for_a_generic_cpu(tmp_path):
    script = tmp_path / "press.py"
    script.write_text(PRESS)
    runs = {}
    host = {key: value for key, value in os.environ.items() if key != "NUMBA_CPU_NAME"}
    generic = {**host, "NUMBA_CPU_NAME": "generic", "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    for name, env in (("host", host), ("generic", generic)):
        subprocess.run([sys.executable, str(script), str(tmp_path / f"{name}.npz")], env=env, check=True,
                       timeout=600)
        with np.load(tmp_path / f"{name}.npz") as data:
            runs[name] = dict(data)
    assert np.abs(runs["host"]["forces"]).max() > 0.05  # the tool pressed
    for key in ("positions", "forces"):
        np.testing.assert_array_equal(runs["host"][key], runs["generic"][key])
