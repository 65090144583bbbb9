"""Motion: lookahead planning and joint-space segmentation, as array functions.

- :mod:`moves`: machine-frame move blocks (``MoveBlock``);
- :mod:`limits`: per-move caps (Cartesian, per module through the Jacobian, extruder) and chord steps;
- :mod:`junction`: cornering speeds (junction deviation);
- :mod:`lookahead`: vectorised backward/forward passes;
- :mod:`trapezoid`: planned moves and their timing;
- :mod:`planner`: the streaming planner (bounded lookahead);
- :mod:`program`: reader items -> planned moves and commands, homing;
- :mod:`segments`: planned moves -> joint-space segments (``PlannedSegments``);
- :mod:`pipeline`: reader items -> segments (whole blocks with command marks, or a strictly ordered
  stream), with an encode hook.
"""

from cdprhost.motion.limits import Caps, MoveCaps, move_caps
from cdprhost.motion.moves import MoveBlock
from cdprhost.motion.pipeline import PipelineTotals, SegmentBlock, segment_blocks, segment_program
from cdprhost.motion.planner import Planner
from cdprhost.motion.program import (
    MarkedMoves,
    ProgramPlanner,
    flushes_motion,
    home_position,
    plan_program,
    read_items,
)
from cdprhost.motion.segments import PlannedSegments, Segmenter, SegmentState, segment_moves
from cdprhost.motion.trapezoid import PlannedMoves

__all__ = [
    "Caps",
    "MarkedMoves",
    "MoveBlock",
    "MoveCaps",
    "PipelineTotals",
    "PlannedMoves",
    "PlannedSegments",
    "Planner",
    "ProgramPlanner",
    "SegmentBlock",
    "SegmentState",
    "Segmenter",
    "flushes_motion",
    "home_position",
    "move_caps",
    "plan_program",
    "read_items",
    "segment_blocks",
    "segment_moves",
    "segment_program",
]
