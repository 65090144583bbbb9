"""A fast version of bench/calibration.py: planned poses calibrate the whole workspace."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import REPO, load_script


@pytest.fixture(scope="module")
def bench():
    return load_script(REPO / "bench" / "calibration.py", "bench_calibration")


def test_planned_poses_reach_the_accuracy_targets(bench, sim_model, plan4, plan12):
    sets = {"Table 1": bench.TABLE1_POSES, "planned 4": plan4.fit_poses, "planned 12": plan12.poses}
    scores = bench.session_scores(sim_model, sets, range(8), noise_mm=0.05)
    med = {k: float(np.median(v)) for k, v in scores.items()}
    assert med["planned 12"] < 0.15
    assert med["planned 4"] < 0.4
    assert (
        med["Table 1"] > 20 * med["planned 4"]
    )  # the paper's coplanar set: errors of millimetres or worse
    assert med["Table 1"] > 50 * med["planned 12"]
    assert np.isfinite(scores["planned 4"]).all() and np.isfinite(scores["planned 12"]).all()
    assert med["before"] > 1.0
