"""Experience memory (DESIGN §5): the SQLite store, the retrieval index and neighbourhood,
returns, per-sender caps, the advantage estimators' inputs, and how records are shared
between daemons (per episode and per round)."""
