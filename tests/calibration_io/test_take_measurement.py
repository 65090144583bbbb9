"""measure_effector: registration, gaps, outliers, standard errors, refusals with reasons."""

from __future__ import annotations

import numpy as np
import pytest

from cdprhost.calibration.acceptance import AcceptanceLimits
from cdprhost.calibration.mocap.readers import Take, read_take
from cdprhost.calibration.mocap.registration import rotation_about_z
from cdprhost.calibration.mocap.takes import effector_centroid, measure_effector
from cdprhost.calibration.takes import TakeRejected
from cdprhost.sim.mocap_noise import MocapNoise
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
        assert m.n_frames_used >= 85 and m.base_fit_rms_mm < 0.05 and m.spread_mm < 0.1
        # 3 markers of 0.03 mm over 90 frames: 0.002 mm from the frames, about as much again
        # from the registration (base markers averaged, carried through the 210 mm lever)
        assert np.all((m.se_frames > 0.001) & (m.se_frames < 0.004)), m.se_frames
        assert np.all(m.se_registration > 0) and np.all(m.se >= m.se_frames)
        assert m.sigma_mm == pytest.approx(float(np.sqrt(np.mean(m.se**2))))


def test_outlier_frames_are_dropped_and_reported():
    rng = np.random.default_rng(8)
    take = synthesize_take(POINT, jitter_mm=0.02, n_frames=60, rng=rng)
    bad = shifted(take, [3, 17, 40], ["EE:E1", "EE:E2", "EE:E3"], np.array([4.0, -3.0, 6.0]))
    m = measure_effector(bad, mocap_config())
    np.testing.assert_allclose(m.point, POINT, atol=0.02)
    assert m.n_frames_used == 57 and any("3 outlier frame(s)" in w for w in m.warnings)
    plain = bad.positions.reshape(60, -1).mean(axis=0) - take.positions.reshape(60, -1).mean(axis=0)
    assert np.abs(plain).max() > 0.2  # a plain mean would have been pulled off


def test_a_marker_lost_in_a_gap_is_stood_in_for_by_the_others():
    eff = np.array([[0.0, 10.0, 0.0], [10.0, 0.0, 0.0], [-10.0, 0.0, 5.0]])
    frames = np.repeat(eff[None], 20, axis=0) + np.array([1.0, 2.0, 3.0])
    frames[5:9, 0] = np.nan  # one marker gone for 4 frames
    frames[12, :] = np.nan  # every marker gone
    centre, partial = effector_centroid(frames)
    assert partial == 4
    np.testing.assert_allclose(
        np.delete(centre, 12, axis=0), np.tile(eff.mean(0) + [1, 2, 3], (19, 1))
    )
    assert np.isnan(centre[12]).all()


def test_runs_of_gaps_are_skipped_in_any_format(tmp_path):
    rng = np.random.default_rng(9)
    noise = MocapNoise(jitter_mm=0.05, gap_fraction=0.06, gap_run_frames=12)
    take = synthesize_take(
        POINT,
        realism=noise,
        n_frames=240,
        rate_hz=120,
        rng=rng,
        path=tmp_path / "g.csv",
        format="motive-csv",
        units="Meters",
    )
    assert np.isnan(take.positions).any()
    m = measure_effector(read_take(tmp_path / "g.csv"), mocap_config())
    assert any("completed from the effector markers" in w for w in m.warnings)
    np.testing.assert_allclose(m.point, POINT, atol=5 * float(np.max(m.se)) + 0.002)


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


def test_reject_creeping_effector_as_drift():
    rng = np.random.default_rng(11)
    take = synthesize_take(POINT, jitter_mm=0.02, n_frames=120, rng=rng)
    creep = np.linspace(0.0, 0.3, 120)[:, None, None] * np.array([1.0, 0.0, 0.0])
    pos = take.positions.copy()
    pos[:, 3:] += creep
    moving = Take(take.marker_names, pos, take.times_s, "drift.csv", take.format)
    with pytest.raises(
        TakeRejected, match=r"drift\.csv: effector crept 0\.[23]\d\d mm over"
    ) as err:
        measure_effector(moving, mocap_config())
    assert err.value.reason == "drift"
    # below the relevance limit it is kept, however significant
    small = Take(
        take.marker_names,
        take.positions + creep / 10 * [[[0]] * 3 + [[1]] * 3],
        take.times_s,
        "s",
        take.format,
    )
    assert measure_effector(small, mocap_config()).drift_mm < 0.05
    jumpy = shifted(
        take, list(range(0, 120, 3)), ["EE:E1", "EE:E2", "EE:E3"], np.array([0.0, 0.0, 3.0])
    )
    with pytest.raises(TakeRejected, match="effector not static: 40 of 120 frames") as err:
        measure_effector(jumpy, mocap_config())
    assert err.value.reason == "outliers"


def test_reject_vibrating_effector_by_spread():
    rng = np.random.default_rng(12)
    take = synthesize_take(POINT, jitter_mm=2.0, n_frames=200, rng=rng)
    with pytest.raises(TakeRejected, match=r"frames scatter 2\.\d+ mm RMS") as err:
        measure_effector(take, mocap_config())
    assert err.value.reason == "spread"
    assert measure_effector(take, mocap_config(max_spread_mm=3.0)).spread_mm > 1.0


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
    with pytest.raises(TakeRejected, match="only 6 usable frames") as err:
        measure_effector(short, mocap_config())
    assert err.value.reason == "too-few-frames"
    assert measure_effector(short, mocap_config(min_frames=5)).n_frames_used == 6
    pos = take.positions.copy()
    pos[:20, take.index("EE:E1") :] = np.nan  # the effector unseen in 2/3 of the frames
    with pytest.raises(TakeRejected, match=r"seen in only 10 of 30 frames") as err:
        measure_effector(Take(take.marker_names, pos, take.times_s, "t", "c3d"), mocap_config())
    assert err.value.reason == "gaps"


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
