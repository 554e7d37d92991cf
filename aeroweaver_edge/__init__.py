"""AeroWeaver-edge: a decentralised runtime that lets LLMs fly UAV swarms through skills.

The public surface is small on purpose: configs, the daemon and the CLI. Everything else
is internal and may change between releases.
"""

__version__ = "0.1.0"
