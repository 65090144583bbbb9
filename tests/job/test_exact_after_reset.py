"""Where a killed job's device stopped, when the device has reset since (issue 30, item 3):
the counters its BOOT announced, or a clear refusal when it kept none that fit."""

from __future__ import annotations

import pytest

from cdprhost.job.exact import DeviceStop, ExactPlaceUnknown, device_stop, reset_notice
from cdprhost.job.resume import SAVED_WHILE_PRINTING, ResumePoint
from cdprhost.link import DeviceStatus
from firmware_protocol.codes import BootCause
from firmware_protocol.messages import Boot, Flag

OLD_BOOT, NEW_BOOT = 0x1111, 0x2222


def _point(reason: str = SAVED_WHILE_PRINTING, segment: int = 500) -> ResumePoint:
    return ResumePoint(
        gcode="/x.gcode",
        sha256="0" * 64,
        reason=reason,
        last_line=40,
        last_layer=3,
        position=(0.0, 0.0, 1.0),
        steps=(0, 0, 0, 0),
        hotend_target=200.0,
        bed_target=60.0,
        suggested_layer=3,
        point=(1.0, 2.0, 0.9),
        e_mm=12.0,
        device_segment=segment,
        boot_id=OLD_BOOT,
        first_segment=10,
    )


def _status(segments: int, flags: int = 0) -> DeviceStatus:
    zero = (0, 0, 0, 0)
    return DeviceStatus(flags, 64, 0, segments, 0.0, zero, 20, 0, 20, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0)


def _boot(cause: BootCause, valid: bool, segments: int = 0) -> Boot:
    return Boot(NEW_BOOT, cause, 2, 1, int(valid), segments // 2, segments)


def test_the_same_boot_still_faulted_names_its_own_counter_as_before():
    found = _status(620, Flag.FAULT)
    assert device_stop(_point(), found, OLD_BOOT, None) == DeviceStop(620)
    assert device_stop(_point(), _status(620), OLD_BOOT, None) is None  # fault cleared since


def test_after_an_external_reset_the_record_in_boot_names_the_segment():
    boot = _boot(BootCause.EXTERNAL_RESET, True, 620)
    stop = device_stop(_point(), _status(0), NEW_BOOT, boot)
    assert stop is not None and stop.segment == 620 and "external reset" in stop.reset
    assert "kept its record (last executed segment 620)" in reset_notice(boot)


def test_after_a_power_loss_the_resume_is_refused_naming_the_layer():
    boot = _boot(BootCause.POWER_ON, False)
    with pytest.raises(ExactPlaceUnknown, match="kept no record.*--resume-from-layer 3"):
        device_stop(_point(), _status(0), NEW_BOOT, boot)
    assert reset_notice(boot) == ""  # a power-on is no reset to report


def test_a_record_older_than_the_point_is_of_a_later_boot_and_refused():
    boot = _boot(BootCause.EXTERNAL_RESET, True, 0)  # reset again before this connect
    with pytest.raises(ExactPlaceUnknown, match="more than once"):
        device_stop(_point(), _status(0), NEW_BOOT, boot)


def test_another_boot_whose_boot_was_not_heard_is_refused():
    with pytest.raises(ExactPlaceUnknown, match="was not read"):
        device_stop(_point(), _status(0), NEW_BOOT, None)


def test_a_boot_heard_with_the_same_id_is_still_a_restart():
    """Two power-ons with the same EEPROM boot count give the same id (the simulator's):
    a BOOT at connect means no session since, so not the point's."""
    boot = Boot(OLD_BOOT, BootCause.POWER_ON, 2, 1, 0, 0, 0)
    with pytest.raises(ExactPlaceUnknown, match="kept no record"):
        device_stop(_point(), _status(0), OLD_BOOT, boot)


def test_the_host_s_own_last_point_needs_no_record():
    """A point the host saved when the job ended (a failure, a cancel) is exact already."""
    point = _point(reason="DeviceReset: the device reset")
    assert device_stop(point, _status(0), NEW_BOOT, _boot(BootCause.POWER_ON, False)) is None
