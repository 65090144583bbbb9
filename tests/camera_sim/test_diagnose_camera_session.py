"""`cdprhost diagnose` on a rendered camera session: a hidden drive_scale is named with its
values, the verdict is ``named`` and the held-out gap above the noise floor shrinks."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cdprhost.cli.main import main
from cdprhost.sim.camera.scene import rig_for_size
from cdprhost.sim.camera.session import write_camera_session
from cdprhost.sim.scenarios import hidden_truth, measurement_tour


@pytest.mark.slow
def test_hidden_drive_scale_is_named_from_pictures(sim_model, tmp_path):
    rng = np.random.default_rng(3)
    truth = hidden_truth(sim_model, rng, "drive_scale")
    eps = truth.effects.vectors[0]
    rig = rig_for_size((960, 540))
    poses = measurement_tour(sim_model, 40, rng)
    poses = poses[rig.visible(poses)][:30]
    session = tmp_path / "s"
    write_camera_session(
        session, truth, sim_model, poses, rig=rig, frames_per_take=3, supersample=1
    )
    report = tmp_path / "d.json"
    main(["diagnose", str(session), "--profile", "paper-simulation", "--json", str(report)])
    d = json.loads(report.read_text())
    assert d["effects"][:1] == ["drive_scale"], d["where"]
    lo, hi = np.asarray(d["parameters"]["drive_scale"]["ci95_vector"]).T
    assert np.all((lo <= eps) & (eps <= hi)), (lo, eps, hi)
    assert d["verdict"] == "named"
    floor = d["noise_floor_mm"]
    gap_before = np.sqrt(max(d["heldout_rms_before_mm"] ** 2 - floor**2, 0.0))
    gap_after = np.sqrt(max(d["heldout_rms_after_mm"] ** 2 - floor**2, 0.0))
    assert gap_after < 0.9 * gap_before  # the gap above the noise floor shrinks
