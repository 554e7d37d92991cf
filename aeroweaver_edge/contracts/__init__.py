"""The contracts every part of the runtime shares, at the bottom of the package: the ports
the daemon's core talks to, what a round observes and decides, every wire payload and key,
the skill-package API, the shared defaults and the two kinds of user-facing error. Nothing
here imports anything above it (tests/test_layering.py)."""
