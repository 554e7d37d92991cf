"""The paper's LLM baselines, run as *selectors* (DESIGN §12): a baseline-only central node
on the mesh decides, every UAV still lists its own options, executes the chosen skill
through its own executor and safety gate, and holds when the choice is missing or invalid.

* ``centralized``: one central LLM call per round for every controlled UAV, from the team's
  observations (as each UAV perceived them) and the full skill catalogue.
* ``hmas2``: a central plan, one local review per UAV (a local LLM call in its daemon, from
  its own observation), one central revision, then execution (Chen et al. 2024, adapted).

Modules: ``protocol`` (prompts, JSON schemas, answer parsing), ``json_chat`` (schema'd
chat calls with a fallback), ``central`` (the central node: gathers a round's asks, runs a
policy, answers), ``centralized`` and ``hmas2`` (one policy each), ``remote`` (the UAV's
``Selector`` that asks the central node), ``wiring`` (start them for a simulated run).
"""

from __future__ import annotations

from typing import Final, Literal

Baseline = Literal["centralized", "hmas2"]
BASELINES: Final[tuple[Baseline, ...]] = ("centralized", "hmas2")
CENTRAL_NODE: Final = "central"
"""The central node's identity name on the mesh (never the Commander's)."""

__all__ = ["BASELINES", "CENTRAL_NODE", "Baseline"]
