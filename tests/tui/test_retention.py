"""What the UI lets go of (issue 23, "stop means stop": its memory grew with every print).

Retention properties, not memory figures (those are in ``bench/tui_memory.py``): a finished
print's job object, and the render caches of widgets the UI removed, can be collected; the
embedded device holds a bounded record. (The render caches were held by Textual, up to 1024
of them, before :mod:`cdprhost.tui.widgets.render_caches`; the job objects never were: that
test guards it.)
"""

from __future__ import annotations

import gc
import weakref

import pytest

pytest.importorskip("cdprhost.job.runner", reason="the print runner has not landed yet")

from textual.widgets._footer import FooterKey

from cdprhost.job.state import JobState
from cdprhost.tui.control.live import DEVICE_RECORD_KEEP, LiveBackend
from cdprhost.tui.screens.dialogs import ConfirmScreen

from .conftest import make_app, wait_for
from .parts import small_part


async def test_a_finished_print_leaves_nothing_of_its_job_behind(tmp_path):
    part = tmp_path / "part.gcode"
    part.write_text(small_part(layers=2), encoding="utf-8")
    backend = LiveBackend(
        "paper-prototype",
        speedup=None,
        job_options={"resume_dir": tmp_path / "resume", "log_path": tmp_path / "job.jsonl"},
    )
    jobs: list[weakref.ref] = []
    make_job = backend.make_job

    def tracked(*args, **kwargs):
        job = make_job(*args, **kwargs)
        jobs.append(weakref.ref(job))
        return job

    backend.make_job = tracked  # type: ignore[method-assign]
    app = make_app(backend, open_file=str(part))
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_for(pilot, lambda s: s.connected and s.file.preflight is not None, timeout=30)
        for n in (1, 2):
            await pilot.press("s")
            await wait_for(pilot, lambda s: isinstance(app.screen, ConfirmScreen), what="ask")
            await pilot.press("y")
            state = await wait_for(
                pilot,
                lambda s, n=n: s.job_id == n and s.job.state.finished and len(s.history) >= n,
                timeout=120,
            )
            assert state.job.state is JobState.DONE, state.job.reason
        await pilot.pause(0.2)
        gc.collect()
        assert len(jobs) == 2
        assert jobs[0]() is None, [type(r).__name__ for r in gc.get_referrers(jobs[0]())]
        assert backend.link.device.record.keep == DEVICE_RECORD_KEEP


async def test_removed_keys_leave_no_render_cache_behind(fake_backend):
    app = make_app(fake_backend, connect_on_start=False)
    async with app.run_test(size=(120, 40)) as pilot:
        await pilot.pause()
        keys = list(app.screen.query(FooterKey))
        assert keys
        old = [weakref.ref(k) for k in keys]
        caches = [weakref.ref(k._styles_cache) for k in keys]
        del keys
        app.screen.refresh_bindings()  # the key bar composes new keys (as on each job state)
        for _ in range(5):
            await pilot.pause()
        still = [k for k in (ref() for ref in old) if k is not None and k.is_attached]
        assert not still, "the key bar composed no new keys"
        del still
        gc.collect()
        alive = sum(ref() is not None for ref in caches)
        assert alive == 0, f"{alive} of {len(caches)} removed keys' render caches still held"
