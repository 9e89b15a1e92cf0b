"""Shared fixtures: simulated time, a local transport, and hypothesis profiles."""
from __future__ import annotations

import hashlib
import os
from collections.abc import Callable, Coroutine, Iterator
from typing import Any, TypeVar

import pytest
from dds_domain import domain_env
from hypothesis import HealthCheck, settings

from node_transport.clock import Clock, run_with_clock, simulated_clock

T = TypeVar("T")

settings.register_profile("ci", deadline=None, max_examples=200, suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("dev", deadline=None, max_examples=60, suppress_health_check=[HealthCheck.too_slow])
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "dev"))


@pytest.fixture(autouse=True)
def kept_verdicts(tmp_path_factory: pytest.TempPathFactory, request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> None:
    """Each test keeps the dry run's verdicts in a folder of its own (cell_runner/dry_run/verdict_cache.py): a test
    sees the program as a first run does, never a verdict another test or the person running them kept."""
    base = tmp_path_factory.getbasetemp() / "kept_verdicts"
    monkeypatch.setenv("XDG_CACHE_HOME", str(base / hashlib.sha256(request.node.nodeid.encode()).hexdigest()[:16]))


@pytest.fixture
def run_sim() -> Callable[[Callable[[Clock], Coroutine[Any, Any, T]]], T]:
    """Run ``main(clock)`` on a fresh virtual-time loop: waits cost no wall time, runs are deterministic."""

    def run(main: Callable[[Clock], Coroutine[Any, Any, T]]) -> T:
        return run_with_clock(main, simulated_clock())

    return run


@pytest.fixture
def dds_env() -> Iterator[dict[str, str]]:
    """The environment of DDS participants in a domain no other test uses meanwhile, in this session or
    another on this host (dds_domain.py), on loopback only; the domain is given back when the test ends."""
    with domain_env() as env:
        yield env
