"""Shared fixtures for the whole test tree."""

from __future__ import annotations

from collections.abc import AsyncIterator

import pytest

from tests.helpers.zenoh_net import ZenohNet


@pytest.fixture
async def zenoh_net() -> AsyncIterator[ZenohNet]:
    """A fresh loopback mesh namespace; every session opened through it is closed after."""
    net = ZenohNet()
    try:
        yield net
    finally:
        await net.aclose()
