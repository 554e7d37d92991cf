"""The per-UAV daemon: assembly from config (``app``), the service and its loop over rounds
(``uav_daemon``), one decision round (``decision_round``), flight phases through the
Vehicle port, and the latest mission context. It talks to ports only; backends are chosen
in ``app``."""
