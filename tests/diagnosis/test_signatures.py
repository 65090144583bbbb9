import numpy as np
import pytest

from cdprhost.calibration.fitting import CableModelFit
from cdprhost.diagnosis.signatures import (
    analyse_signature,
    confusable_pairs,
    effect_signature,
    fit_jacobian,
    numeric_jacobian,
    principal_correlation,
)
from cdprhost.effects import CATALOGUE
from tests.diagnosis.hidden_effects import SliderOffset


@pytest.fixture(scope="module")
def base_fit(make_session, sim_model):
    _, _, obs = make_session(None, 11)
    return obs, CableModelFit().fit(obs, sim_model)


def test_numeric_jacobian_of_a_known_function():
    a = np.array([[1.0, 2.0], [0.5, -1.0], [3.0, 0.0]])
    jac = numeric_jacobian(
        lambda x: a @ x + np.sin(x[0]), np.array([0.3, -0.2]), np.array([1e-6, 1e-6])
    )
    expected = a.copy()
    expected[:, 0] += np.cos(0.3)
    np.testing.assert_allclose(jac, expected, rtol=1e-7)


def test_fit_jacobian_matches_estimator_covariance(base_fit):
    obs, fit = base_fit
    jac = fit_jacobian(fit, obs)
    cov = np.linalg.inv(jac.T @ jac) * fit.chi2_ / fit.dof_
    np.testing.assert_allclose(np.sqrt(np.diag(cov)), fit.stderr_, rtol=1e-3)


def test_constant_slider_offset_is_absorbed_by_the_initial_lengths(base_fit):
    obs, fit = base_fit
    report = analyse_signature("slider_offset", *effect_signature(fit.model_, obs, SliderOffset()))
    assert report.absorbed and report.unabsorbed_max < 1e-4


@pytest.mark.parametrize("name", list(CATALOGUE))
def test_catalogue_effects_are_not_absorbed_on_a_spread_session(base_fit, name):
    obs, fit = base_fit
    report = analyse_signature(name, *effect_signature(fit.model_, obs, CATALOGUE[name]))
    assert not report.absorbed
    assert report.unabsorbed_min > 0.02


def test_effects_without_context_have_no_signature(base_fit, sim_model):
    obs, fit = base_fit
    from dataclasses import replace

    blind = replace(obs, t_s=None, directions=None)
    for name in ("drift", "backlash"):
        assert analyse_signature(
            name, *effect_signature(fit.model_, blind, CATALOGUE[name])
        ).absorbed


def test_an_effect_is_confusable_with_itself_and_not_with_an_orthogonal_one(base_fit):
    obs, fit = base_fit
    g, s = effect_signature(fit.model_, obs, CATALOGUE["drive_scale"])
    a = analyse_signature("a", g, s)
    b = analyse_signature("b", g, 2.0 * s[:, ::-1])
    assert principal_correlation(a.residual_basis, b.residual_basis) == pytest.approx(1.0, abs=1e-9)
    assert confusable_pairs([a, b]) and confusable_pairs([a, b])[0][:2] == ("a", "b")
    e1 = np.zeros((10, 1))
    e1[0] = 1
    e2 = np.zeros((10, 1))
    e2[1] = 1
    assert principal_correlation(e1, e2) == 0.0
