"""What only ``cdprhost tui --in-process`` did and a TUI on the printer service does too: the
preflight's estimate is for the board the service holds (what it announced), as with the
device in the UI's process. (Diagnose writing its profile on either: test_diagnose_write.)"""

from __future__ import annotations

from cdprhost.tui.control.backend import EMBEDDED
from cdprhost.tui.control.service_backend import ServiceBackend
from tests.service.inprocess import serve_in_thread


def test_the_preflight_estimates_for_the_board_the_service_holds(run_dir, monkeypatch):
    serve_in_thread(monkeypatch)
    backend = ServiceBackend("paper-prototype", speedup=None)
    try:
        assert backend.local._board() is None  # not connected: the profile's own record
        rows = dict(backend.connect(EMBEDDED, 250000))
        board = backend.local._board()
        assert board is not None and board.min_segment_s is not None
        assert f"{board.max_step_rate:,} steps/s" == rows["max step rate"]
        assert board.firmware == rows["firmware"]
        backend.disconnect()
        assert backend.local._board() is None
    finally:
        backend.close()
