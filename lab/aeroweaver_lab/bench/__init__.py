"""Benchmarks that print figures: ``aeroweaver bench run`` (tasks x conditions x seeds, the
paper's evaluation) and the fault, load and cost experiments (``aeroweaver bench NAME``)."""
