"""The one home for wiring world + Commander + daemons (DESIGN §12).

``aeroweaver sim`` (``swarm.run_swarm``), ``aeroweaver mission start [--sim-world]``
(``mission.start_mission``) and the benchmarks build on this package. It is the only layer
that imports both the simulator (``aeroweaver_edge.sim``) and the Commander (``commander``);
neither of those imports the other, and both read tasks from ``aeroweaver_edge.tasks``.
"""
