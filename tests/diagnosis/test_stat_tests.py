import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy import stats

from cdprhost.diagnosis.stat_tests import (
    bic,
    goodness_of_fit_p,
    holm,
    likelihood_ratio_p,
    nested_f_test,
    pearson,
)

p_lists = st.lists(st.floats(0.0, 1.0, allow_nan=False), min_size=1, max_size=12)


def test_holm_matches_hand_computation():
    # sorted p: 0.01, 0.02, 0.03, 0.04 -> 0.04, 0.06, 0.06 (monotone), 0.06
    np.testing.assert_allclose(holm([0.03, 0.01, 0.04, 0.02]), [0.06, 0.04, 0.06, 0.06])


@given(p_lists)
def test_holm_is_bounded_monotone_and_conservative(p):
    adj = holm(p)
    raw = np.asarray(p)
    assert np.all(adj >= raw - 1e-15) and np.all(adj <= 1.0)
    order = np.argsort(raw, kind="stable")
    assert np.all(np.diff(adj[order]) >= -1e-15)
    assert np.all(adj <= np.minimum(raw * len(p), 1.0) + 1e-12)  # never worse than Bonferroni


def test_holm_keeps_nan():
    adj = holm([0.01, np.nan, 0.02])
    assert np.isnan(adj[1]) and adj[0] == pytest.approx(0.02) and adj[2] == pytest.approx(0.02)


def test_nested_f_test_is_the_textbook_f():
    f, p = nested_f_test(150.0, 100.0, 3, 100)
    assert f == pytest.approx((50.0 / 3) / 1.0)
    assert p == pytest.approx(stats.f.sf(f, 3, 100))
    assert nested_f_test(100.0, 100.5, 1, 50)[0] == 0.0  # a worse big model is no evidence


def test_f_test_is_calibrated_under_the_null():
    rng = np.random.default_rng(0)
    dof_big, extra = 105, 3
    chi2_big = rng.chisquare(dof_big, 20000)
    chi2_small = chi2_big + rng.chisquare(extra, 20000)
    p = np.array([nested_f_test(a, b, extra, dof_big)[1] for a, b in zip(chi2_small, chi2_big)])
    assert abs(np.mean(p < 0.01) - 0.01) < 0.004
    assert abs(np.mean(p < 0.1) - 0.1) < 0.012


def test_goodness_of_fit_and_lr_and_bic():
    assert goodness_of_fit_p(108.0, 108) == pytest.approx(stats.chi2.sf(108.0, 108))
    assert np.isnan(goodness_of_fit_p(1.0, 0))
    assert likelihood_ratio_p(120.0, 100.0, 2) == pytest.approx(np.exp(-10.0))
    assert bic(100.0, 12, 120) - bic(100.0, 11, 120) == pytest.approx(np.log(120))


def test_pearson_agrees_with_scipy():
    rng = np.random.default_rng(1)
    x = rng.normal(size=40)
    y = 0.4 * x + rng.normal(size=40)
    r, p = pearson(x, y)
    ref = stats.pearsonr(x, y)
    assert r == pytest.approx(ref.statistic) and p == pytest.approx(ref.pvalue)
    assert pearson(np.ones(10), y[:10]) == (0.0, 1.0)
