"""Cable kinematics as pure functions on numpy arrays (no I/O).

- :mod:`geometry`: ideal IK (lengths, sliders) and closed-form FK;
- :mod:`jacobian`: velocity Jacobian and the identification Jacobian J0;
- :mod:`statics`: cable tensions and their worst case under a_max;
- :mod:`workspace`: membership with the failed rule named;
- :mod:`machine`: :class:`MachineModel`, geometry + statics + effects from a profile.
"""

from cdprhost.kinematics.geometry import (
    CableGeometry,
    cable_lengths,
    fk_from_lengths,
    fk_points,
    ik_sliders,
)
from cdprhost.kinematics.jacobian import (
    identification_jacobian,
    residual_jacobian,
    velocity_jacobian,
)
from cdprhost.kinematics.machine import MachineModel
from cdprhost.kinematics.statics import StaticsParams, tension_bounds, tensions
from cdprhost.kinematics.workspace import RULES, WorkspaceReport, check_workspace

__all__ = [
    "RULES",
    "CableGeometry",
    "MachineModel",
    "StaticsParams",
    "WorkspaceReport",
    "cable_lengths",
    "check_workspace",
    "fk_from_lengths",
    "fk_points",
    "identification_jacobian",
    "ik_sliders",
    "residual_jacobian",
    "tension_bounds",
    "tensions",
    "velocity_jacobian",
]
