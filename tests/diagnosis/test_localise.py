import numpy as np
import pytest

from cdprhost.calibration.fitting import CableModelFit
from cdprhost.diagnosis.localise import describe, localise, periodic_scan
from tests.diagnosis.hidden_effects import PeriodicLeadError


def base_findings(make_session, sim_model, effect, seed, vector=None):
    _, _, obs = make_session(effect, seed, vector=vector)
    fit = CableModelFit().fit(obs, sim_model)
    return localise(fit.model_, obs), fit


def test_drift_shows_up_against_time(make_session, sim_model):
    findings, _ = base_findings(
        make_session, sim_model, "drift", 1, vector=np.array([4e-4, -3e-4, 3e-4])
    )
    assert findings[0].kind == "time"
    kinds = {(f.kind, f.cable) for f in findings}
    assert {("time", 1), ("time", 2), ("time", 3)} <= kinds
    signs = {f.cable: np.sign(f.statistic) for f in findings if f.kind == "time"}
    assert signs == {1: 1.0, 2: -1.0, 3: 1.0}  # residual = measured - model follows +rho t
    assert "grow with time" in findings[0].text or "fall with time" in findings[0].text


def test_backlash_shows_up_against_approach_direction(make_session, sim_model):
    findings, _ = base_findings(
        make_session, sim_model, "backlash", 2, vector=np.array([0.25, 0.0, 0.0])
    )
    top = findings[0]
    assert (top.kind, top.cable) == ("approach direction", 1) and top.statistic < -0.6
    assert "oppose module 1's approach direction" in top.text


def test_periodic_lead_error_is_found_with_its_period(make_session, sim_model):
    vec = np.array([0.2, 0.0, 0.0, 8.0, 0.3, 0.0, 0.0])
    findings, _ = base_findings(make_session, sim_model, PeriodicLeadError(), 3, vector=vec)
    periodic = [f for f in findings if f.kind == "periodic"]
    assert periodic and periodic[0].cable == 1
    assert (
        "period ~8.0 mm" in periodic[0].text
        or "period ~7.9 mm" in periodic[0].text
        or "period ~8.1 mm" in periodic[0].text
    )


def test_periodic_scan_recovers_a_sinusoid_and_ignores_a_line():
    rng = np.random.default_rng(4)
    s = rng.uniform(-150, 20, 40)
    y = 0.15 * np.sin(2 * np.pi * s / 6.0 + 1.0) + 0.01 * s + rng.normal(0, 0.03, 40)
    period, amp, _, p = periodic_scan(s, y)
    assert (
        period == pytest.approx(6.0, rel=0.02) and amp == pytest.approx(0.15, rel=0.2) and p < 1e-6
    )
    assert periodic_scan(s, 0.01 * s + rng.normal(0, 0.03, 40))[3] > 0.01


def test_clean_data_is_described_as_consistent(make_session, sim_model):
    findings, fit = base_findings(make_session, sim_model, None, 4)
    assert findings == [] or all(f.p_value < 0.01 for f in findings)
    text = describe(findings, fit.chi2_, fit.dof_, 0.4)
    assert text.startswith("no disagreement beyond the noise floor")
    assert "no pattern" in describe([], 500.0, 108, 1e-30)
    assert describe([], 140.0, 108, 0.02, explained=True).startswith("a small disagreement")
