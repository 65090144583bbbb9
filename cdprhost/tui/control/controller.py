"""The controller: turns UI requests into backend calls on worker threads, and results into
state; one object made of three parts (:mod:`.link_flow`, :mod:`.print_flow`,
:mod:`.lab_flow`)."""

from __future__ import annotations

from cdprhost.tui.control.lab_flow import LabFlow
from cdprhost.tui.control.print_flow import PrintFlow


class Controller(PrintFlow, LabFlow):
    """UI requests -> backend calls in workers -> state (UI thread)."""
