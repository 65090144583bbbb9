"""Simulated devices other than the Python model: the AVR firmware in simavr."""
