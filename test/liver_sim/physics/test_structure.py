"""The liver's structure (physics.structure): the paper's fixed tet, the nodes' masses, the skin's areas, the kernels'
threads, and the substeps a change raises for an explicit integrator."""
import math

import numba
import numpy as np
import pytest

from liver_sim.physics.model import LiverModel
from liver_sim.physics.settings import ModelParams
from liver_sim.physics.structure import (
    AUTO_PARALLEL_MIN_CORES,
    PARALLEL_MIN_EDGES,
    STABILITY_MARGIN,
    auto_parallel,
    build_structure,
    default_fixed_nodes,
    initial_structure,
    scaled_masses,
)

from meshes import box_mesh, perturbed_state

#: The box is held as in the paper's scene (its central tet fixed), which these tests are written for.
PAPER_SCENE = ModelParams(support="paper")


def test_fixed_nodes_default_to_the_middle_tet_and_stay_put(box):
    fixed = default_fixed_nodes(box)
    assert len(fixed) == 4
    centroid = box.points[fixed].mean(axis=0)
    assert np.linalg.norm(centroid - box.points.mean(axis=0)) < 0.02
    model = LiverModel(box, PAPER_SCENE)
    model.state.positions[:] = perturbed_state(box)[0]
    before = model.state.positions[fixed].copy()
    for _ in range(10):
        model.step_frame(None)
    np.testing.assert_array_equal(model.state.positions[fixed], before)


def test_fixed_nodes_out_of_range_are_refused(box):
    with pytest.raises(ValueError, match="fixed_nodes"):
        LiverModel(box, ModelParams(fixed_nodes=(0, 10_000)))


@pytest.mark.parametrize("solver_threads, parallel", [("one", False), ("all", True), ("auto", False)])
def test_solver_threads_choose_the_kernels_threads(solver_threads, parallel):
    """'one' and 'all' as said; 'auto' by the spring count (a small box: one thread); the implicit step's PCG runs on
    the threads the structure has, and says so."""
    box = box_mesh(3, 3, 3, 0.01)
    model = LiverModel(box, ModelParams(solver_threads=solver_threads))
    assert model.structure.parallel is parallel
    threads = numba.get_num_threads() if parallel else 1
    assert model.structure.solver.threads == threads
    assert ("threads" in model.structure.step_solver) is (threads > 1)
    model.step_frame(None)  # steps on those threads


def test_auto_takes_the_threads_for_a_large_liver_on_four_cores_or_more():
    assert auto_parallel(PARALLEL_MIN_EDGES, AUTO_PARALLEL_MIN_CORES)
    assert not auto_parallel(PARALLEL_MIN_EDGES, 2)  # beside the 1 kHz loops of a 2-core rig: one thread
    assert not auto_parallel(PARALLEL_MIN_EDGES - 1, 64)


def test_scaled_masses_raise_the_light_nodes_and_keep_the_total():
    # mean 0.775 kg, floor 0.4 × 0.775 = 0.31 kg: (1, 1, 1, 0.31) rescaled by 3.1 / 3.31
    masses = scaled_masses(np.array([1.0, 1.0, 1.0, 0.1]), 0.4)
    np.testing.assert_allclose(masses, np.array([1.0, 1.0, 1.0, 0.31]) * 3.1 / 3.31)
    np.testing.assert_array_equal(scaled_masses(np.array([2.0, 3.0]), 0.0), [2.0, 3.0])  # no floor: unchanged


def test_the_skin_nodes_share_the_skin_area_and_the_interior_none(box):
    structure = initial_structure(box, PAPER_SCENE)
    areas = structure.skin_node_area_m2
    assert areas.sum() == pytest.approx(2 * (0.08 * 0.06 + 0.08 * 0.06 + 0.06 * 0.06))  # the box's faces
    interior = np.setdiff1d(np.arange(len(box.points)), box.skin_nodes)
    assert len(interior) and not areas[interior].any()
    assert structure.version == 0 and structure.node_count == len(box.points)


def test_a_change_raises_an_explicit_integrators_substeps_to_the_bound_and_the_first_structure_does_not(box):
    params = ModelParams(support="paper", integrator="symplectic_euler", substeps=1)
    first = initial_structure(box, params)
    assert first.params.substeps == 1 and first.params.dt_s > first.stable_dt_s  # as asked, unstable
    changed = build_structure(box, params, box.skin, first.masses_kg, first.fixed_nodes, version=1)
    bound = changed.stable_dt_s
    needed = math.ceil(first.frame_period_s / (STABILITY_MARGIN * bound))
    assert changed.params.substeps == needed > 1 and changed.version == 1
    assert changed.params.dt_s <= STABILITY_MARGIN * bound
    implicit = build_structure(box, ModelParams(support="paper"), box.skin, first.masses_kg, first.fixed_nodes,
                               version=1)
    assert implicit.params.substeps == 1 and implicit.stable_dt_s == math.inf
