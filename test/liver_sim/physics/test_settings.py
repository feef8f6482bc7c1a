"""The model's constants (physics.settings): Eq. 1's SpringLaw against Fig. 2 and by hand, the step length and the
integrators' substeps, and validate() refusing out-of-range values by the parameter's name."""
import math

import numpy as np
import pytest

from liver_sim.mesh.liver_shape import default_liver
from liver_sim.physics.model import LiverModel
from liver_sim.physics.settings import FIG2_LAW, ModelParams, SpringLaw, TissueProperties


@pytest.mark.parametrize("strain, expected", [(0.0, 0.0), (0.1, 0.085), (0.2, 0.47), (-0.1, -0.085), (0.3, 1.455)])
def test_spring_law_matches_fig2(strain, expected):
    # Fig. 2: λ1 = 50, λ2 = 0.35; F = 50·d³ + 0.35·d
    assert FIG2_LAW.force_n(strain) == pytest.approx(expected)


def test_spring_law_is_linear_below_ten_percent_and_stiffens_beyond():
    small = FIG2_LAW.force_n(0.01) / 0.01
    assert small == pytest.approx(FIG2_LAW.lambda2_n, rel=0.02)
    slope_at = lambda d: (FIG2_LAW.force_n(d + 1e-6) - FIG2_LAW.force_n(d - 1e-6)) / 2e-6  # noqa: E731
    assert slope_at(0.3) > 10 * slope_at(0.0)


def test_spring_law_viscous_term():
    law = SpringLaw(lambda1_n=0.0, lambda2_n=0.0, mu_ns_per_m=2.0)
    assert law.force_n(0.0, 0.5) == pytest.approx(1.0)


def test_spring_law_sums_its_three_terms():
    # F = λ1·d³ + λ2·d + μ·ṗ = 2·0.125 + 3·0.5 + 4·(−0.25) = 0.75 N
    assert SpringLaw(2.0, 3.0, 4.0).force_n(0.5, -0.25) == pytest.approx(0.75)


@pytest.mark.parametrize("change, name", [
    (dict(substeps=0), "substeps"),
    (dict(integrator="rk4"), "integrator"),
    (dict(density_kg_m3=-1.0), "density_kg_m3"),
    (dict(capsule=SpringLaw(math.nan, 1.0, 0.0)), "capsule.lambda1_n"),
    (dict(gravity_m_s2=(0.0, math.inf, 0.0)), "gravity_m_s2"),
])
def test_out_of_range_parameters_are_refused_by_name(change, name):
    with pytest.raises(ValueError, match=name.replace(".", r"\.")):
        ModelParams().with_changes(**change)


def test_an_unknown_solver_threads_is_refused_by_name():
    with pytest.raises(ValueError, match="solver_threads"):
        ModelParams(solver_threads="two").validate()


def test_the_default_is_one_implicit_step_per_frame_and_the_explicit_ones_keep_their_substeps():
    params = ModelParams()
    assert (params.integrator, params.substeps) == ("implicit_euler", 1)
    assert params.with_changes(integrator="symplectic_euler").substeps == 72
    assert params.with_changes(integrator="explicit_euler", substeps=90).substeps == 90
    model = LiverModel(default_liver())
    assert model.structure.stable_dt_s == np.inf and model.structure.implicit


def test_the_step_is_the_frame_divided_into_substeps():
    assert ModelParams(frame_rate_hz=100.0, substeps=4).dt_s == pytest.approx(1.0 / 400.0)
    changed = ModelParams(integrator="symplectic_euler", substeps=10).with_changes(integrator="implicit_euler")
    assert changed.substeps == 1  # a new integrator without substeps takes its own


def test_the_elements_need_the_implicit_integrator_and_material_constants():
    with pytest.raises(ValueError, match="tissue_law"):
        ModelParams(tissue_law="fem", integrator="symplectic_euler").validate()
    with pytest.raises(ValueError, match="tissue_law"):
        ModelParams(tissue_law="fem", spring_constants="paper").validate()
    with pytest.raises(ValueError, match="tissue_law 'neo_hookean'"):
        ModelParams(tissue_law="neo_hookean", integrator="symplectic_euler").validate()
    with pytest.raises(ValueError, match="tissue_law"):
        ModelParams(tissue_law="hyperfoam").validate()


def test_the_surface_contact_needs_the_implicit_integrator():
    with pytest.raises(ValueError, match="contact_model 'surface'"):
        ModelParams(contact_model="surface", integrator="symplectic_euler").validate()
    with pytest.raises(ValueError, match="contact_model"):
        ModelParams(contact_model="volume").validate()
    assert ModelParams(contact_model="surface").validate().contact_model == "surface"


def test_validate_names_the_parameter():
    with pytest.raises(ValueError, match="parenchyma_young_modulus_kpa"):
        TissueProperties(parenchyma_young_modulus_kpa=-1.0).validate()
    with pytest.raises(ValueError, match="parenchyma_poisson_ratio"):
        ModelParams(tissue=TissueProperties(parenchyma_poisson_ratio=0.5)).validate()
    with pytest.raises(ValueError, match="spring_constants"):
        ModelParams(spring_constants="per_spring").validate()


def test_tearing_parameters_are_validated():
    for name in ("tear_strain_parenchyma", "tear_strain_capsule"):
        for bad in (0.0, -1.0, math.nan, math.inf):
            with pytest.raises(ValueError, match=name):
                ModelParams(**{name: bad}).validate()
    with pytest.raises(ValueError, match="tearing"):
        ModelParams(tearing=1).validate()
