"""Every default the runtime shares, written once (paper and docs/notes/mpe-tasks.md values).

Config models, the CLI, the simulator, the Commander and the skills import these names
instead of repeating the numbers, so changing a default is a one-line edit here.
"""

from __future__ import annotations

from typing import Final

# --- arena and flight -------------------------------------------------------------------
ARENA_HALF_M: Final = 70.0
"""Half the side of the authors' 140 x 140 m arena, centred on the local origin."""
ALTITUDE_M: Final = 5.0
"""Fixed flight level above the local origin (NED down = -5 m)."""
MAX_SPEED_MPS: Final = 11.0
MAX_ACCEL_MPS2: Final = 30.0
MIN_SEPARATION_M: Final = 2.0
ROUND_S: Final = 0.5
"""One decision round: the world advances this much between decisions."""
MAX_ROUNDS: Final = 24
"""Episode horizon of the paper's experiments."""

# --- sensing and talking ----------------------------------------------------------------
SENSING_RADIUS_M: Final = 45.0
"""Neighbour/entity sensing range of every role but the world-communication leader."""
COMM_RADIUS_M: Final = 55.0
"""Peer-to-peer communication range (same team), unless a task routes a pair further."""
MESSAGE_TTL_ROUNDS: Final = 8

# --- MPE reward scaling -----------------------------------------------------------------
MPE_UNIT_M: Final = 70.0
"""Metres per MPE unit: the 140 m arena maps onto [-1, 1]^2, where MPE resets live."""

# --- selection and experience -----------------------------------------------------------
BETA: Final = 0.8
"""Weight of the experience correction (0: the plain selector)."""
GAMMA: Final = 0.95
"""Discount of the stored returns."""
NEIGHBOURHOOD: Final = 32
"""Experience records retrieved per decision."""
HISTORY_ROUNDS: Final = 8
"""Rounds of its own interaction history each agent keeps in its context (0: none)."""
HOLD_SKILL: Final = "hold_position"
"""The skill every UAV always has, and what any invalid choice becomes."""

# --- Commander --------------------------------------------------------------------------
TOP_K: Final = 8
"""Task skills activated per UAV (``hold_position`` comes on top)."""
CATALOGUE_SIZE: Final = 12
"""Skills in the task-level candidate catalogue A^t."""
MAX_UAVS: Final = 50
"""Largest swarm a task record, the simulator and the CLI accept."""

# --- simulated runs ---------------------------------------------------------------------
DEADLINE_S: Final = 30.0
"""Seconds a UAV may take for one round before the world treats it as holding."""
