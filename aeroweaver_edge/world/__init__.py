"""The kinematic world: point-mass UAVs at a fixed altitude in a local NED frame. The tasks
score it, the simulator advances it, the emulator and the local vehicle fly on it."""
