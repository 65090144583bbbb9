"""Acceptance on hidden-effect data (issue 6, item 6).

The simulator builds a true machine with one effect hidden (realistic magnitudes,
scenarios.MAGNITUDES), a 40-pose session spread over the workspace in a shuffled
order, 20-60 s per pose, 0.05 mm mocap noise. The workflow is not told which
effect; it must name it in >= 95 % of 40 seeds per effect, say ``none`` on clean
data in >= 95 %, bring the held-out error down to <= 1.3x the noise floor (in
>= 95 % of seeds, see below), and
answer ``unexplained`` for an effect outside the catalogue.
"""

from __future__ import annotations

import numpy as np
import pytest

from cdprhost.diagnosis.workflow import FAST, DiagnosisSettings, diagnose
from cdprhost.effects import CATALOGUE
from tests.diagnosis.hidden_effects import PeriodicLeadError, periodic_vector

SEEDS = range(2000, 2040)


def run(make_session, sim_model, effect, seed, settings=FAST, vector=None):
    _, _, obs = make_session(effect, seed, vector=vector)
    return diagnose(obs, sim_model, settings=settings)


@pytest.mark.slow
@pytest.mark.parametrize("effect", list(CATALOGUE))
def test_names_the_hidden_catalogue_effect(make_session, sim_model, effect):
    named, ratios, misses = 0, [], []
    for seed in SEEDS:
        d = run(make_session, sim_model, effect, seed)
        if d.verdict == "named" and d.effects == (effect,):
            named += 1
            ratios.append(d.final.heldout_rms_mm / d.noise_floor_mm)
            assert d.base.heldout_rms_mm > d.final.heldout_rms_mm  # the gap shrinks...
        else:
            misses.append((seed, d.verdict, d.effects, d.ambiguous_between))
    assert named >= 0.95 * len(SEEDS), misses
    # ...and closes to the noise floor. Per seed the ratio has a tail: a pose near
    # z_min (cables ~7 deg from horizontal) can carry 5x the average held-out
    # variance, so about 1 % of seeds exceed 1.3 (none of these 40).
    ratios = np.asarray(ratios)
    assert np.mean(ratios <= 1.3) >= 0.95 and np.median(ratios) <= 1.1


@pytest.mark.slow
def test_says_none_on_clean_data(make_session, sim_model):
    verdicts = [run(make_session, sim_model, None, seed) for seed in SEEDS]
    none = [d for d in verdicts if d.verdict == "none"]
    assert len(none) >= 0.95 * len(SEEDS), [
        (d.verdict, d.effects) for d in verdicts if d.verdict != "none"
    ]
    assert np.mean([d.final.heldout_rms_mm <= 1.3 * d.noise_floor_mm for d in none]) >= 0.95
    assert all(d.effect is None and not d.final.effects for d in none)


@pytest.mark.slow
def test_out_of_catalogue_effect_is_unexplained(make_session, sim_model):
    verdicts = []
    for seed in SEEDS:
        vec = periodic_vector(np.random.default_rng(seed + 50_000), (0.1, 0.2))
        verdicts.append(run(make_session, sim_model, PeriodicLeadError(), seed, vector=vec))
    unexplained = [d for d in verdicts if d.verdict == "unexplained"]
    assert len(unexplained) >= 0.95 * len(SEEDS)
    assert all(d.effect is None for d in verdicts if d.verdict != "named")
    # 'where' points at the slider-position pattern in most sessions
    assert sum("repeat with slider position" in d.where for d in unexplained) >= 0.8 * len(
        unexplained
    )


@pytest.mark.parametrize("effect", [None, *CATALOGUE])
def test_full_settings_agree(make_session, sim_model, effect):
    d = run(make_session, sim_model, effect, 7, settings=DiagnosisSettings())
    assert d.verdict == ("none" if effect is None else "named")
    assert d.effects == (() if effect is None else (effect,))
    assert all(
        np.isfinite(c.heldout_rms_mm) for c in d.candidates
    )  # every candidate cross-validated
    assert d.final.heldout_rms_mm <= 1.3 * d.noise_floor_mm
