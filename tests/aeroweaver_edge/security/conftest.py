"""One swarm PKI (and a rogue one with the same names, another CA) for the security tests."""

from __future__ import annotations

from collections.abc import AsyncIterator

import pytest

from aeroweaver_edge.security.identity import SwarmPki, default_members
from tests.helpers.secure_net import SecureNet

SWARM = "s"


@pytest.fixture(scope="session")
def swarm_pki(tmp_path_factory: pytest.TempPathFactory) -> SwarmPki:
    return SwarmPki.create(tmp_path_factory.mktemp("pki"), SWARM, default_members(3))


@pytest.fixture(scope="session")
def rogue_pki(tmp_path_factory: pytest.TempPathFactory) -> SwarmPki:
    """Same identity names, its own CA: what an outsider can make for themselves."""
    return SwarmPki.create(tmp_path_factory.mktemp("rogue"), SWARM, default_members(3))


@pytest.fixture
async def secure_net(swarm_pki: SwarmPki) -> AsyncIterator[SecureNet]:
    net = SecureNet(swarm_pki)
    try:
        yield net
    finally:
        await net.aclose()
