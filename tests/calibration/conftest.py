"""Shared fixtures of the calibration tests: the paper's truth, planned pose sets (cached)."""

from __future__ import annotations

import numpy as np
import pytest

from cdprhost.calibration.planning import plan_poses
from cdprhost.kinematics import CableGeometry, MachineModel
from tests.conftest import PAPER_TRUTH_OUTLETS


def paper_truth_geometry() -> CableGeometry:
    lengths = np.linalg.norm(np.array([0.0, 0.0, 330.0]) - PAPER_TRUTH_OUTLETS, axis=1)
    return CableGeometry(PAPER_TRUTH_OUTLETS.copy(), lengths)


@pytest.fixture(scope="session")
def paper_truth(sim_model) -> MachineModel:
    return sim_model.with_geometry(paper_truth_geometry())


@pytest.fixture(scope="session")
def plan4(sim_model):
    return plan_poses(sim_model, 4, n_check=2)


@pytest.fixture(scope="session")
def plan12(sim_model):
    return plan_poses(sim_model, 12)
