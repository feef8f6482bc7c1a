"""The same bits whatever the CPU numba compiles for and whatever the threads (issue 45): a press on a liver large
enough for the two-level preconditioner ends on the same positions and forces to the bit compiled for the host and for
a generic x86-64 (NUMBA_CPU_NAME=generic, a cache of its own: the child compiles every kernel of a frame anew, a few
minutes of one core), and on one thread, two and three (NUMBA_NUM_THREADS), with the springs and with the
neo-Hookean elements."""
import os
import platform
import subprocess
import sys

import numpy as np
import pytest

#: The press, run in a child: prints nothing, writes positions and forces of every frame to argv[1]; argv[2] the
#: solver_threads, argv[3] the tissue_law.
PRESS = """
import sys
import numpy as np
from liver_sim.mesh.landmarks import press_anchor
from liver_sim.mesh.liver_shape import build_liver
from liver_sim.physics.contact.tool_geometry import ToolPose
from liver_sim.physics.model import LiverModel
from liver_sim.physics.settings import ModelParams

def press(path, threads, law):
    mesh = build_liver(2500)
    model = LiverModel(mesh, ModelParams(preconditioner="two_level", solver_threads=threads, tissue_law=law))
    anchor, radius = press_anchor(mesh), model.tool.shape.radius_m
    positions, forces = [], []
    for k in range(40):
        result = model.step_frame(ToolPose(anchor + [0.0, 0.0, radius - 0.008 * min(1.0, (k + 1) / 30)]))
        positions.append(model.state.positions.copy())
        forces.append(result.tool_forces_n[0])
    assert model.structure.step_solver.startswith("pcg two-level")
    np.savez(path, positions=np.array(positions), forces=np.array(forces))

if __name__ == "__main__":
    press(*sys.argv[1:])
"""


def presses(tmp_path, runs: dict[str, tuple[dict, str, str]]) -> dict[str, dict]:
    """The press's frames of each named run (environment, solver_threads, tissue_law), each in a child."""
    script = tmp_path / "press.py"
    script.write_text(PRESS)
    frames = {}
    for name, (env, threads, law) in runs.items():
        subprocess.run([sys.executable, str(script), str(tmp_path / f"{name}.npz"), threads, law], env=env,
                       check=True, timeout=600)
        with np.load(tmp_path / f"{name}.npz") as data:
            frames[name] = dict(data)
    return frames


def assert_same_bits(frames: dict[str, dict]) -> None:
    first, *others = frames.values()
    assert np.abs(first["forces"]).max() > 0.05  # the tool pressed
    for other in others:
        for key in ("positions", "forces"):
            np.testing.assert_array_equal(first[key], other[key])


HOST = {key: value for key, value in os.environ.items() if key not in ("NUMBA_CPU_NAME", "NUMBA_NUM_THREADS")}


@pytest.mark.skipif(platform.machine() not in ("x86_64", "AMD64"), reason="a generic x86-64 target")
def test_a_press_gives_the_same_bits_compiled_for_the_host_and_for_a_generic_cpu(tmp_path):
    generic = {**HOST, "NUMBA_CPU_NAME": "generic", "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    assert_same_bits(presses(tmp_path, {"host": (HOST, "one", "springs"), "generic": (generic, "one", "springs")}))


@pytest.mark.parametrize("law", ["springs", "neo_hookean"])
def test_a_press_gives_the_same_bits_on_one_two_and_three_threads(tmp_path, law):
    assert_same_bits(presses(tmp_path, {
        "one": (HOST, "one", law),
        "two": ({**HOST, "NUMBA_NUM_THREADS": "2"}, "all", law),
        "three": ({**HOST, "NUMBA_NUM_THREADS": "3"}, "all", law)}))
