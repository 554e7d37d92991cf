"""The decision side of a daemon: candidates, selector arithmetic, prompt, memory."""
