"""Fixtures of the AVR firmware tests: the firmware and harness built once (the
conformance suite's fixture)."""

from tests.conformance.conftest import avr_built

__all__ = ["avr_built"]
