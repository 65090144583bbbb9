"""A program restarted at a point (``--resume``) is sent the whole print's segments after the
move it restarts in: the same module steps, the same extruder increments and the same
durations, tick for tick (issue 30: the resumed record equals an uninterrupted print's).

The extruder keeps the file's absolute E through the restart (re-zeroing it rounded other
numbers: a step moved between neighbours) and each move's duration is rounded on its own
(rounding absolute times moved a tick between neighbours, the restart's clock starting
elsewhere)."""

from __future__ import annotations

import numpy as np
import pytest

from cdprhost.job.resume_items import INSERTED_LINE, Restart
from cdprhost.kinematics.machine import MachineModel
from cdprhost.motion.pipeline import segment_program
from cdprhost.motion.program import read_items
from cdprhost.motion.segments import PlannedSegments
from tests.e2e.processes import square_part


def _segments(items, profile, model) -> PlannedSegments:
    parts = [o for o in segment_program(items, profile, model) if isinstance(o, PlannedSegments)]
    return PlannedSegments(
        *(
            np.concatenate([getattr(p, f) for p in parts])
            for f in PlannedSegments.__dataclass_fields__
        )
    )


@pytest.mark.parametrize("at", [137, 290, 451])
def test_the_restarted_program_is_the_whole_prints_after_the_cut_move(tmp_path, proto_profile, at):
    proto_model = MachineModel.from_profile(proto_profile)
    gcode = square_part(tmp_path / "part.gcode", layers=3)
    whole = _segments(read_items(gcode, proto_profile, proto_model), proto_profile, proto_model)
    origin = np.asarray(proto_profile.build_volume.bed_origin, dtype=float)
    line = int(whole.line[at])
    restart = Restart(
        read_items(gcode, proto_profile, proto_model),
        line=line,
        point=tuple(whole.point[at] - origin),
        e_mm=float(whole.e[at]),
    )
    again = _segments(restart, proto_profile, proto_model)
    # the whole print after the move of segment ``at``, and the restart after its own cut move
    after = int(np.flatnonzero(whole.line[at + 1 :] != line)[0]) + at + 1
    program = np.flatnonzero(again.line != INSERTED_LINE)
    cut_end = int(program[np.flatnonzero(again.line[program] != line)[0]])
    tail, same = whole.take(slice(after, None)), again.take(slice(cut_end, None))
    assert len(tail) == len(same) > 100
    np.testing.assert_array_equal(same.steps_abs[:, :3], tail.steps_abs[:, :3])
    np.testing.assert_array_equal(same.delta, tail.delta)  # the extruder's included
    np.testing.assert_array_equal(same.ticks, tail.ticks)
    np.testing.assert_array_equal(same.ramp, tail.ramp)
    # the extruder fed from the restart point to the end: the whole print's
    e0 = int(np.rint(whole.e[at] * proto_profile.extruder.steps_per_mm))
    assert int(again.delta[program[0] :, 3].sum()) == int(whole.steps_abs[-1, 3]) - e0
