"""Fixtures for the diagnosis tests: simulated hidden-effect sessions at array level."""

from __future__ import annotations

import numpy as np
import pytest

from cdprhost.sim.scenarios import hidden_truth, simulate_session


def hidden_session(model, effect, seed, vector=None, n_poses=40, noise_mm=0.05):
    """(truth, poses, observations) of one simulated session with ``effect`` hidden."""
    rng = np.random.default_rng(seed)
    truth = hidden_truth(model, rng, effect, vector)
    poses, obs = simulate_session(truth, model, rng, n_poses=n_poses, noise_mm=noise_mm)
    return truth, poses, obs


@pytest.fixture(scope="session")
def make_session(sim_model):
    return lambda effect, seed, **kw: hidden_session(sim_model, effect, seed, **kw)
