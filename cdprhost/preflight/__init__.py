"""Preflight: check a whole G-code program before anything moves."""

from cdprhost.preflight.report import PreflightReport, Violation
from cdprhost.preflight.run import Preflight, preflight, preflight_items

__all__ = ["Preflight", "PreflightReport", "Violation", "preflight", "preflight_items"]
