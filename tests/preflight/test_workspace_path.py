"""PathChecker internals: the tension certificate and the fallback for uncertified profiles."""

from __future__ import annotations

import numpy as np
import pytest

from cdprhost.kinematics import MachineModel
from cdprhost.kinematics.workspace import build_volume_excess
from cdprhost.motion.moves import MoveBlock
from cdprhost.preflight.workspace import PathChecker, tension_certificate
from cdprhost.profile import MachineProfile


@pytest.mark.parametrize("name", ["sim_profile", "proto_profile"])
def test_shipped_profiles_are_certified_and_dense_sampling_agrees(name, request):
    model = MachineModel.from_profile(request.getfixturevalue(name))
    certified, gradient = tension_certificate(model)
    assert certified and 0 < gradient < 100
    rng = np.random.default_rng(1)
    pts = rng.uniform([-85, -50, 110], [85, 99, 330], (200_000, 3))
    pts = pts[build_volume_excess(pts, 170.0, 110.0, 330.0) <= 0]
    report = model.check(pts, np.zeros_like(pts))  # sliders at 0: only the tension rule can fail
    assert report.ok.all()


def weak_profile(profile: MachineProfile) -> MachineProfile:
    data = profile.model_dump()
    data["statics"]["tension_min_n"] = 10.0
    return MachineProfile.model_validate(data)


def test_uncertified_profile_samples_moves_near_the_tension_limit(sim_profile):
    model = MachineModel.from_profile(weak_profile(sim_profile))
    checker = PathChecker(model)
    assert not checker.volume_certified
    low = np.array([[0.0, 0.0, 150.0], [10.0, 0.0, 150.0]])  # deep inside: certified by margins
    assert checker.check(MoveBlock.from_arrays(low[:1], low[1:])) == []
    assert checker.sampled_moves == 0
    # a long move in the band where margins are small gets sampled (and here passes)
    z = 270.0
    a, b = np.array([-20.0, 0.0, z]), np.array([20.0, 20.0, z])
    assert model.check(np.array([a, b])).ok.all()
    failures = checker.check(MoveBlock.from_arrays(a[None, :], b[None, :]))
    assert checker.sampled_moves == 1
    samples = a + np.linspace(0, 1, 60)[:, None] * (b - a)
    assert (failures == []) == bool(model.check(samples).ok.all())
