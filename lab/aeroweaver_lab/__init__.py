"""AeroWeaver lab: research tools built on the runtime, shipped apart from it (the
``aeroweaver-lab`` distribution). The benchmark (``bench``: runner, report, conditions,
fault and load experiments), the paper's baselines as selectors (``baselines``) and the
skill-retrieval evaluation. It imports the runtime; the runtime finds it only through
entry points (``aeroweaver_edge.runtime.plugins``)."""
