"""Process plumbing every command shares: owned background tasks and lost-party handling
(``lifecycle``), signals (``signals``), systemd's notify protocol, logging, run
directories nobody leaves behind, atomic strict JSON, credential redaction, and the
entry points through which another distribution (the lab) adds commands and selectors."""
