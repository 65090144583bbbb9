"""A front end that attaches to a running print shows the print's elapsed time, not the
time since it attached (the service's events carry when the job started)."""

from __future__ import annotations

import io
import time

from cdprhost.cli.progress_view import ProgressView
from cdprhost.job.state import JobState, Planned, Progress, StateChanged


def test_a_late_view_counts_from_the_jobs_start():
    out = io.StringIO()
    start = time.monotonic() - 125.0  # the job began two minutes before the view
    view = ProgressView(out)
    with view:
        view.update(StateChanged(JobState.PREFLIGHT, at=start - 1))
        view.update(Planned(4, 100, 100.0, 10.0))
        view.update(StateChanged(JobState.PRINTING, at=start))
        view.update(Progress(10, 20, 1, 50.0))
    line = next(x for x in out.getvalue().splitlines() if x.startswith("printing"))
    assert "elapsed 0:02:0" in line, line
