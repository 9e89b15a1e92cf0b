"""The DDS domains of the tests: two tests running at once -- in one session or two -- never hold one domain, and
a claim ends with its holder however the holder ends (dds_domain.py).  Claims here are kept in a folder of the
test's own, so the test never takes a domain another test running meanwhile needs."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from dds_domain import NoFreeDomain, claimed_domain, dds_env

ROOT = Path(__file__).resolve().parent.parent
IDS = range(10, 16)

#: Another session: claims every id but two, says which, holds them until its stdin closes or it is killed.
HOLDER = """
import contextlib, sys
sys.path.insert(0, sys.argv[2])
from dds_domain import claimed_domain
from pathlib import Path
with contextlib.ExitStack() as stack:
    held = [stack.enter_context(claimed_domain(Path(sys.argv[1]), range(10, 16))) for _ in range(4)]
    print(",".join(map(str, held)), flush=True)
    sys.stdin.read()
"""


def test_a_domain_another_session_holds_is_never_claimed_and_is_free_once_that_session_dies(tmp_path: Path) -> None:
    holder = subprocess.Popen([sys.executable, "-c", HOLDER, str(tmp_path), str(ROOT / "test")],
                              stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout is not None
        held = {int(d) for d in holder.stdout.readline().split(",")}
        assert len(held) == 4 and held <= set(IDS)
        with claimed_domain(tmp_path, IDS) as first, claimed_domain(tmp_path, IDS) as second:
            assert {first, second} == set(IDS) - held  # the two left, one each
            with pytest.raises(NoFreeDomain, match="all 6 DDS domain ids 10..15 are claimed"), claimed_domain(tmp_path, IDS):
                pass
        holder.kill()  # killed, not stopped: the kernel gives its claims back
        holder.wait(10.0)
        with claimed_domain(tmp_path, IDS) as a, claimed_domain(tmp_path, IDS) as b, claimed_domain(tmp_path, IDS) as c:
            assert len({a, b, c}) == 3
    finally:
        if holder.poll() is None:
            holder.kill()
            holder.wait(10.0)
        assert holder.stdout is not None
        holder.stdout.close()
        assert holder.stdin is not None
        holder.stdin.close()


def test_a_claim_is_given_back_when_the_test_ends_and_the_environment_stays_on_this_host(tmp_path: Path) -> None:
    with claimed_domain(tmp_path, [12]) as domain:
        assert domain == 12
        env = dds_env(domain)
        assert env["ROS_DOMAIN_ID"] == "12" and env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST" and "127.0.0.1" in env["CYCLONEDDS_URI"]
    with claimed_domain(tmp_path, [12]) as again:
        assert again == 12


def test_a_bench_holds_its_domain_until_it_ends() -> None:
    """A bench claims its domain for its whole process (hold_domain); once it ends, the domain is free."""
    code = f"import sys; sys.path.insert(0, {str(ROOT / 'test')!r}); from dds_domain import hold_domain; print(hold_domain(), flush=True); sys.stdin.read()"
    bench = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert bench.stdout is not None and bench.stdin is not None
        domain = int(bench.stdout.readline())
        with pytest.raises(NoFreeDomain), claimed_domain(ids=[domain]):
            pass
        bench.stdin.close()  # the bench ends
        assert bench.wait(10.0) == 0
        with claimed_domain(ids=[domain]) as again:
            assert again == domain
    finally:
        if bench.poll() is None:
            bench.kill()
            bench.wait(10.0)
        assert bench.stdout is not None
        bench.stdout.close()
