"""measure_effector: averaging, outlier rejection, take rejection, noise model of synthetic takes."""

from __future__ import annotations

import numpy as np
import pytest

from cdprhost.calibration.readers import Take, read_take
from cdprhost.calibration.registration import rotation_about_z
from cdprhost.calibration.takes import (
    AcceptanceLimits,
    TakeRejected,
    measure_effector,
    robust_inliers,
)
from cdprhost.sim.synthetic_session import motive_world_pose, synthesize_take
from tests.calibration_io.helpers import mocap_config

POINT = np.array([-35.0, 60.0, 210.0])


def shifted(take: Take, frames, markers, delta) -> Take:
    pos = take.positions.copy()
    idx = [take.index(m) for m in markers]
    pos[np.ix_(frames, idx)] += delta
    return Take(take.marker_names, pos, take.times_s, take.source, take.format)


def test_static_take_measures_the_point_in_any_mocap_world():
    rng = np.random.default_rng(5)
    for pose in (motive_world_pose(), (rotation_about_z(2.5), np.array([-50.0, 900.0, 3.0]))):
        take = synthesize_take(POINT, mocap_pose=pose, jitter_mm=0.03, n_frames=90, rng=rng)
        m = measure_effector(take, mocap_config())
        np.testing.assert_allclose(m.point, POINT, atol=0.02)
        assert m.n_frames_used >= 85 and m.base_fit_rms_mm < 0.05 and m.spread_mm < 0.2
        # centroid of 3 markers (0.017 mm) plus the base fit's share, which the 210 mm lever amplifies
        assert np.all((m.std > 0.017) & (m.std < 0.05)), m.std
        assert (m.sem < m.std).all()


def test_outlier_frames_are_dropped_and_reported():
    rng = np.random.default_rng(8)
    take = synthesize_take(POINT, jitter_mm=0.02, n_frames=60, rng=rng)
    bad = shifted(take, [3, 17, 40], ["EE:E1", "EE:E2", "EE:E3"], np.array([4.0, -3.0, 6.0]))
    m = measure_effector(bad, mocap_config())
    np.testing.assert_allclose(m.point, POINT, atol=0.02)
    assert m.n_frames_used == 57 and any("3 outlier frame(s)" in w for w in m.warnings)
    plain = bad.positions.reshape(60, -1).mean(axis=0) - take.positions.reshape(60, -1).mean(axis=0)
    assert np.abs(plain).max() > 0.2  # a plain mean would have been pulled off


def test_robust_inliers_mask():
    pts = np.zeros((20, 3))
    pts[:, 0] = np.linspace(-0.01, 0.01, 20)
    pts[7] = [0.0, 5.0, 0.0]
    mask = robust_inliers(pts, 5.0, 0.005)
    assert not mask[7] and mask.sum() == 19


def test_gapped_frames_are_skipped(tmp_path):
    rng = np.random.default_rng(9)
    take = synthesize_take(
        POINT,
        jitter_mm=0.02,
        n_frames=80,
        gaps_fraction=0.05,
        rng=rng,
        path=tmp_path / "g.csv",
        format="motive-csv",
        units="Meters",
    )
    m = measure_effector(read_take(tmp_path / "g.csv"), mocap_config())
    n_ok = int(np.isfinite(take.positions).all(axis=(1, 2)).sum())
    assert m.n_frames_used <= n_ok < 80 and any("skipped for gaps" in w for w in m.warnings)
    np.testing.assert_allclose(m.point, POINT, atol=0.03)


def test_reject_misplaced_base_markers_naming_file_and_marker(tmp_path):
    rng = np.random.default_rng(10)
    base = {
        "Base:F1": (0.0, 300.0, 0.0),
        "Base:F2": (-259.8, -150.0, 0.0),
        "Base:F3": (259.8, -150.0, 0.0),
        "Base:F4": (0.0, 0.0, 0.0),
    }
    path = tmp_path / "take7.csv"
    take = synthesize_take(
        POINT, base_markers={**base, "Base:F4": (0.0, 0.0, 6.0)}, rng=rng, path=path
    )
    config = mocap_config().model_copy(update={"base_markers": base})
    with pytest.raises(
        TakeRejected, match=r"take7\.csv: base-marker fit RMS .*\(largest misfit: Base:F4"
    ) as err:
        measure_effector(read_take(path), config)
    assert err.value.reason == "base-fit" and err.value.exit_code == 2
    loose = AcceptanceLimits(max_base_rms_mm=5.0)  # thresholds are configurable
    assert measure_effector(take, config, loose).base_fit_rms_mm > 0.5


def test_reject_moving_effector():
    rng = np.random.default_rng(11)
    take = synthesize_take(POINT, jitter_mm=0.02, n_frames=60, rng=rng)
    drift = np.linspace(0.0, 2.0, 60)[:, None, None] * np.array([1.0, 0.0, 0.0])
    pos = take.positions.copy()
    pos[:, 3:] += drift
    moving = Take(take.marker_names, pos, take.times_s, "drift.csv", take.format)
    with pytest.raises(
        TakeRejected, match=r"drift\.csv: effector not static: frames spread"
    ) as err:
        measure_effector(moving, mocap_config())
    assert err.value.reason == "not-static"
    jumpy = shifted(
        take, list(range(0, 60, 3)), ["EE:E1", "EE:E2", "EE:E3"], np.array([0.0, 0.0, 3.0])
    )
    with pytest.raises(TakeRejected, match="effector not static: 20 of 60 frames") as err:
        measure_effector(jumpy, mocap_config())


def test_reject_missing_never_seen_and_too_few_frames():
    rng = np.random.default_rng(12)
    take = synthesize_take(POINT, n_frames=30, rng=rng)
    renamed = mocap_config().model_copy(
        update={
            "effector": mocap_config().effector.model_copy(
                update={"markers": ("EE:E1", "EE:E2", "EE:E4")}
            )
        }
    )
    with pytest.raises(
        TakeRejected, match=r"marker\(s\) EE:E4 not in the take \(it has: Base:F1"
    ) as err:
        measure_effector(take, renamed)
    assert err.value.reason == "missing-marker"
    pos = take.positions.copy()
    pos[:, take.index("Base:F2")] = np.nan
    with pytest.raises(TakeRejected, match=r"Base:F2 never seen") as err:
        measure_effector(Take(take.marker_names, pos, take.times_s, "t", "c3d"), mocap_config())
    short = synthesize_take(POINT, n_frames=6, rng=rng)
    with pytest.raises(TakeRejected, match="only 6 of 6 frames") as err:
        measure_effector(short, mocap_config())
    assert err.value.reason == "too-few-frames"
    assert measure_effector(short, mocap_config(min_frames=5)).n_frames_used == 6


def test_noise_mm_is_the_std_of_the_measured_point():
    """``noise_mm`` survives averaging (a static per-take error); per-frame jitter does not."""
    rng = np.random.default_rng(13)
    cfg = mocap_config()
    errors = np.array(
        [
            measure_effector(
                synthesize_take(POINT, noise_mm=0.05, jitter_mm=0.02, n_frames=30, rng=rng), cfg
            ).point
            - POINT
            for _ in range(300)
        ]
    )
    std = errors.std(axis=0)
    assert np.all((std > 0.044) & (std < 0.057)), std
    assert np.abs(errors.mean(axis=0)).max() < 0.012
