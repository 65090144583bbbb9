"""cdprhost: host software for a cable-driven parallel robot (CDPR) 3D printer."""

__version__ = "0.1.0"
