"""The garbage collector kept from pausing a stream (cdprhost/link/collector.py)."""

from __future__ import annotations

import gc
import threading
import weakref

import numpy as np
import pytest

from cdprhost.link import collector, quiet_collection
from cdprhost.sim.embedded import open_embedded
from firmware_protocol.ramp_profile import RAMP_CONSTANT
from firmware_protocol.segments import SegmentBatch


class Clock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


@pytest.fixture(autouse=True)
def _thawed():
    assert not collector.streaming() and gc.get_freeze_count() == 0
    yield
    gc.unfreeze()


def _cycle() -> list:
    a: list = []
    a.append(a)  # only the cyclic collector frees it
    return a


def test_a_quiet_section_freezes_what_the_process_holds_and_thaws_it_at_its_end():
    held = [_cycle() for _ in range(1000)]
    with quiet_collection():
        assert collector.streaming()
        # what the process held is out of the collector's generations
        assert gc.get_freeze_count() >= len(held)
        assert sum(len(gc.get_objects(g)) for g in range(3)) < gc.get_freeze_count()
    assert not collector.streaming()
    assert gc.get_freeze_count() == 0


def test_garbage_made_while_frozen_is_collected_once_thawed():
    class Watched:
        pass

    with quiet_collection():
        w = Watched()
        w.me = w  # type: ignore[attr-defined]
        alive = [True]
        weakref.finalize(w, alive.clear)
        collector.keep_pauses_short(clock=lambda: 1e12)  # refrozen, w with it
        del w
        gc.collect()
        assert alive  # frozen: kept for now
    gc.collect()
    assert not alive  # thawed: collected


def test_what_a_stream_makes_is_frozen_again_every_refreeze_s():
    clock = Clock()
    with quiet_collection(clock=clock):
        before = gc.get_freeze_count()
        made = [_cycle() for _ in range(2000)]
        collector.keep_pauses_short(clock=clock)
        assert gc.get_freeze_count() == before  # too early
        clock.t += collector.REFREEZE_S
        collector.keep_pauses_short(clock=clock)
        assert gc.get_freeze_count() >= before + len(made)
    del made


def test_outside_a_quiet_section_nothing_is_frozen():
    collector.keep_pauses_short(clock=lambda: 1e12)
    assert gc.get_freeze_count() == 0


def test_sections_nest_and_overlap_across_threads_and_thaw_only_when_the_last_ends():
    inner_done = threading.Event()
    outer_may_end = threading.Event()

    def other() -> None:
        with quiet_collection():
            inner_done.set()
            outer_may_end.wait(5)

    with quiet_collection():
        t = threading.Thread(target=other)
        t.start()
        assert inner_done.wait(5)
        with quiet_collection():
            pass
        assert gc.get_freeze_count() > 0  # two still open
    assert collector.streaming() and gc.get_freeze_count() > 0  # the thread's still open
    outer_may_end.set()
    t.join(5)
    assert not collector.streaming() and gc.get_freeze_count() == 0


def test_an_exception_inside_still_thaws():
    with pytest.raises(RuntimeError):
        with quiet_collection():
            raise RuntimeError("the stream failed")
    assert not collector.streaming() and gc.get_freeze_count() == 0


def test_queue_segments_streams_inside_a_quiet_section_and_leaves_none_open():
    seen = []
    link = open_embedded()
    try:
        real = link.feed

        def feed(*a, **k):
            seen.append(collector.streaming())
            return real(*a, **k)

        link.feed = feed  # type: ignore[method-assign]
        n = 20
        deltas = np.zeros((n, 4), np.int64)
        deltas[:, 0] = 40
        ramps = np.full(n, RAMP_CONSTANT, np.int64)
        ramps[-1] = 255
        link.queue_segments(SegmentBatch(np.full(n, 1000, np.int64), deltas, ramps))
        link.wait_idle(30)
    finally:
        link.close()
    assert seen and all(seen)
    assert not collector.streaming() and gc.get_freeze_count() == 0


def test_a_print_job_streams_inside_a_quiet_section(tmp_path, monkeypatch):
    from cdprhost.gcode.sample_parts import square_walls
    from cdprhost.job.runner import PrintJob
    from cdprhost.link import segment_feed
    from cdprhost.profile import load_profile

    seen: list[bool] = []
    real = segment_feed.keep_pauses_short
    monkeypatch.setattr(
        segment_feed, "keep_pauses_short", lambda: (seen.append(collector.streaming()), real())
    )
    part = tmp_path / "part.gcode"
    part.write_text(square_walls(2))
    job = PrintJob(part, load_profile("paper-prototype"), open_embedded)
    result = job.run()
    assert result.status == "completed", result.reason
    assert seen and all(seen)
    assert not collector.streaming() and gc.get_freeze_count() == 0
