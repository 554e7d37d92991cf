"""Benchmark tasks (notes/mpe-tasks.md). Each maps a task name to a :class:`Task` class."""

from aeroweaver_edge.sim.tasks.base import Metrics, Task, uav_id
from aeroweaver_edge.sim.tasks.coverage import CoverageTask

TASKS: dict[str, type[Task]] = {CoverageTask.name: CoverageTask}


def make_task(
    name: str, n_uavs: int = 3, *, altitude_m: float = 5.0, max_rounds: int | None = None
) -> Task:
    """Instantiate a task by name; unknown names list the known ones."""
    try:
        cls = TASKS[name]
    except KeyError:
        raise ValueError(f"unknown task {name!r}; known: {', '.join(sorted(TASKS))}") from None
    return cls(n_uavs, altitude_m=altitude_m, max_rounds=max_rounds)


__all__ = ["TASKS", "CoverageTask", "Metrics", "Task", "make_task", "uav_id"]
