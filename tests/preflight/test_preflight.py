"""Preflight: the whole path against the workspace, extrusion sanity, commands, summary."""

from __future__ import annotations

import numpy as np
import pytest

from cdprhost.gcode import GcodeError
from cdprhost.kinematics import MachineModel
from cdprhost.preflight import preflight
from cdprhost.profile import MachineProfile

from .helpers import line_of, square_body, write_program


def test_clean_square_passes(tmp_path, sim_profile, sim_model):
    path = write_program(tmp_path, square_body())
    r = preflight(path, sim_profile, sim_model)
    assert r.ok and r.violations == [] and r.violations_total == 0
    assert r.moves == 6
    assert r.filament_mm == pytest.approx(0.033 * 160, rel=1e-6)
    assert r.estimated_time_s > 160 / 30  # 160 mm at 30 mm/s plus the travel from home
    assert r.print_box_gcode.min == pytest.approx(
        (-20, -20, 0.3)
    ) and r.print_box_gcode.max == pytest.approx((20, 20, 0.3))


def test_unreachable_move_in_the_middle_is_named_first(tmp_path, sim_profile, sim_model):
    body = square_body()
    body.insert(4, "G1 X150 Y0 F6000")  # outside the build triangle
    path = write_program(tmp_path, body)
    r = preflight(path, sim_profile, sim_model)
    bad = line_of(path, "G1 X150 Y0 F6000")
    assert not r.ok
    first = r.violations[0]
    assert first.line == bad
    assert [v.line for v in r.violations] == sorted(v.line for v in r.violations)
    # the path leaves the workspace (the build triangle) long before reaching the point:
    # the reported point is the first failing one along the move, within 1 mm of the edge
    a, b = np.array([20.0, 20.0, 110.3]), np.array([150.0, 0.0, 110.3])
    p = np.array(first.point)
    t = np.dot(p - a, b - a) / np.dot(b - a, b - a)
    assert np.linalg.norm(a + t * (b - a) - p) < 1e-3
    assert first.rule == sim_model.check(p[None, :]).rule_name(0) == "build_volume"
    before = a + (t - 1.0 / np.linalg.norm(b - a)) * (b - a)
    assert sim_model.check(before[None, :]).ok[0]


def test_too_tall_move_is_refused(tmp_path, sim_profile, sim_model):
    body = square_body() + ["G1 Z225 F600"]  # 335 mm in the machine frame, above z_max = 330
    path = write_program(tmp_path, body)
    r = preflight(path, sim_profile, sim_model)
    assert not r.ok
    v = r.violations[0]
    assert v.line == line_of(path, "G1 Z225 F600")
    assert v.rule == "build_volume"
    assert v.point[2] > 330.0
    assert "by" in v.detail


def test_malformed_line_is_an_input_error_naming_line_and_column(tmp_path, sim_profile, sim_model):
    body = square_body()
    body.insert(3, "G1 X1.2.3 Y5")
    path = write_program(tmp_path, body)
    with pytest.raises(GcodeError) as err:
        preflight(path, sim_profile, sim_model)
    assert err.value.line == line_of(path, "G1 X1.2.3 Y5")
    assert err.value.exit_code == 2
    assert f":{err.value.line}:" in str(err.value)


def test_first_travel_from_home_is_checked(tmp_path, sim_profile, sim_model):
    path = write_program(tmp_path, ["G1 X0 Y0 Z300 F3000"], start=[])
    r = preflight(path, sim_profile, sim_model)
    assert not r.ok and r.violations[0].line == 1


def dip_profile(profile: MachineProfile, model: MachineModel, centre: np.ndarray) -> MachineProfile:
    """Module 3 may not shorten its cable to ``centre``'s length (1 mm short of it)."""
    s3 = float(model.ik(centre[None, :])[0, 2])
    data = profile.model_dump()
    travel = [list(t) for t in data["drive"]["travel_mm"]]
    travel[2][0] = s3 + 1.0
    data["drive"]["travel_mm"] = travel
    return MachineProfile.model_validate(data)


def test_violation_between_valid_endpoints_is_found(tmp_path, sim_profile, sim_model):
    centre = np.array([0.0, 0.0, 200.0])
    profile = dip_profile(sim_profile, sim_model, centre)
    model = MachineModel.from_profile(profile)
    outlet = model.geometry.outlets[2]
    toward = centre - outlet
    side = np.cross(toward, [0.0, 0.0, 1.0])
    side /= np.linalg.norm(side)
    a, b = centre - 40 * side, centre + 40 * side
    assert model.check(np.array([a, b])).ok.all()  # both endpoints are fine
    g = lambda p: f"X{p[0]:.4f} Y{p[1]:.4f} Z{p[2] - 110:.4f}"  # noqa: E731
    body = [f"G1 {g(a)} F6000", f"G1 {g(b)} F6000", "G1 Z150 F600"]
    path = write_program(tmp_path, body)
    r = preflight(path, profile, model)
    assert not r.ok
    v = r.violations[0]
    assert v.line == line_of(path, body[1]) and v.rule == "slider_travel"
    assert np.linalg.norm(np.array(v.point) - centre) < 30.0  # failing part is around the centre
    assert "module 3" in v.detail


def test_uncertified_tension_region_is_checked(tmp_path, sim_profile):
    data = sim_profile.model_dump()
    data["statics"]["tension_min_n"] = (
        10.0  # the top of the volume no longer holds 10 N under a_max
    )
    profile = MachineProfile.model_validate(data)
    model = MachineModel.from_profile(profile)
    body = square_body() + ["G1 Z215 F600"]
    path = write_program(tmp_path, body)
    r = preflight(path, profile, model)
    assert not r.ok
    assert r.violations[0].rule == "tension"
    # the travel from home at z = 327 starts outside the workspace too: reported at the first move
    assert {v.rule for v in r.violations} == {"tension"}


def test_cold_extrusion(tmp_path, sim_profile, sim_model):
    path = write_program(tmp_path, square_body(), start=["G28", "G90", "M82", "G92 E0"])
    r = preflight(path, sim_profile, sim_model)
    cold = [v for v in r.violations if v.rule == "cold_extrusion"]
    assert len(cold) == 1 and "unset" in cold[0].detail
    path = write_program(tmp_path, square_body(), start=["M104 S150", "G28", "G92 E0"])
    r = preflight(path, sim_profile, sim_model)
    assert [v.rule for v in r.violations] == ["cold_extrusion"] and "150 C" in r.violations[
        0
    ].detail


def test_volumetric_flow_limit(tmp_path, sim_profile, sim_model):
    path = write_program(
        tmp_path, square_body(e_per_mm=0.2, feed=6000)
    )  # 0.2 mm/mm at 100 mm/s: 48 mm^3/s
    r = preflight(path, sim_profile, sim_model)
    flows = [v for v in r.violations if v.rule == "volumetric_flow"]
    assert flows and all("exceeds 25" in v.detail for v in flows)
    assert r.max_volumetric_flow_seen_mm3_s == pytest.approx(
        0.2 * 100 * np.pi * 1.75**2 / 4, rel=0.01
    )


def test_heater_targets_and_unknown_commands(tmp_path, sim_profile, sim_model):
    body = ["M73 P10", "M104 S300", "M999"] + square_body() + ["M73 P20"]
    path = write_program(tmp_path, body)
    r = preflight(path, sim_profile, sim_model)
    rules = {v.rule: v for v in r.violations}
    assert rules["temperature"].line == line_of(path, "M104 S300")
    assert "by 15 C" in rules["temperature"].detail
    assert "unknown_command" not in rules  # the default policy: a warning, skipped when printing
    assert [(w.word, w.kind, w.lines) for w in r.warnings] == [
        ("M999", "unknown_command", [line_of(path, "M999")])
    ]
    assert [(n.word, n.count) for n in r.notes] == [("M73", 2)]
    strict = preflight(path, sim_profile, sim_model, strict=True)
    rules = {v.rule: v for v in strict.violations}
    assert rules["unknown_command"].line == line_of(path, "M999") and strict.warnings == []


def test_fixture_passes_with_both_profiles(fixture_gcode, sim_profile, proto_profile):
    times = {}
    for profile in (sim_profile, proto_profile):
        r = preflight(fixture_gcode, profile)
        assert r.ok, r.violations[:3]
        assert r.moves == 122769 and r.layers == 149
        assert r.moves_sampled_densely <= 2  # only the long first travel from home needs sampling
        times[profile.name] = r.estimated_time_s
        assert (
            0.95 * 8587.2 < r.estimated_time_s < 1.05 * 8587.2
        )  # Klipper's estimate, same Cartesian limits
    assert r.filament_mm == pytest.approx(independent_filament(fixture_gcode), abs=1e-3)
    assert r.filament_mm == pytest.approx(12173.73, abs=0.01)  # the slicer's header


def independent_filament(path) -> float:
    """Forward extrusion of the moves that also move the effector (not the primes after
    a retraction) of an absolute-E file with G92 E resets, read line by line."""
    e = total = 0.0
    for raw in open(path):
        words = raw.split(";", 1)[0].split()
        if not words:
            continue
        if words[0] in ("G1", "G0"):
            moves = any(w[0] in "XYZ" for w in words[1:])
            for w in words[1:]:
                if w[0] == "E":
                    v = float(w[1:])
                    total += max(v - e, 0.0) if moves else 0.0
                    e = v
        elif words[0] == "G92":
            for w in words[1:]:
                if w[0] == "E":
                    e = float(w[1:])
    return total
