"""Task rewards evaluated on the kinematic world's state (mpe2 scenario functions)."""

from aeroweaver_edge.sim.rewards.mpe import MPE_UNIT_M, MpeRewardModel, SpreadRewards, UnitScale

__all__ = ["MPE_UNIT_M", "MpeRewardModel", "SpreadRewards", "UnitScale"]
