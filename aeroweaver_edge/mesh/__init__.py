"""The talk side: one asyncio facade over a Zenoh session (``session``), a UAV's view of its
peers over it (``peers``) or in memory (``peer_memory``), the receive rules every channel
shares (``inbox``), the bounded hand-off from Zenoh's threads (``intake``), link timeouts and
the endpoint syntax users type."""
