"""The simulated KR C4 the KUKA RSI back end starts itself when no real controller is given.

Without a robot at hand (``--robot kuka-rsi`` without ``rsi_listen``) the back end runs the simulator
(:mod:`.simulator`) as its own process in real time, or on a thread of this process (real time, or lockstep for
tests).  Starting it, reading what it says, knowing why it stopped -- so that a silence is reported as that stop,
not as a timeout -- and ending it are the same whatever the back end then does with the robot, so they live here.
"""
from __future__ import annotations

import asyncio
import json
import logging
import subprocess
import sys
from dataclasses import dataclass

from node_transport.clock import real_clock
from robot_bridges.kuka_rsi.config import RsiConfig, RsiRoles
from robot_bridges.kuka_rsi.external import RobotLink
from robot_bridges.kuka_rsi.krc_model import RsiContext
from robot_bridges.kuka_rsi.loop_events import LoopEvents
from robot_bridges.kuka_rsi.realtime import SIMULATOR_PRIORITY
from robot_bridges.kuka_rsi.sim_faults import Faults, Quirks
from robot_bridges.kuka_rsi.sim_network import SimulatorThread
from robot_bridges.kuka_rsi.spoofer import Flood

#: The back end's logger: what its simulated controller says is the back end's to report, under its name.
log = logging.getLogger("robot_bridges.kuka_rsi.backend")


@dataclass(frozen=True)
class SimulatorSpec:
    """A simulated controller the back end starts itself (``--robot kuka-rsi`` without a real one)."""

    runner: str = "process"  # "process": python -m ...simulator (real time); "thread": in-process
    accelerated: bool = False  # lockstep (thread runner only)
    context: RsiContext = RsiContext()
    faults: Faults = Faults()
    quirks: Quirks = Quirks()  # a misbehaving peer, for tests and demonstrations
    flood: Flood = Flood()  # a second sender on the controller's host (another port), for tests and demonstrations
    peer: str = "kr-c4"  # the controller it behaves like (context and quirks already say so; a process is told again)
    rt_priority: int = SIMULATOR_PRIORITY  # SCHED_FIFO of a simulator process, above the loop's (a controller is hard real time); 0: none


def quirk_arguments(faults: Faults, quirks: Quirks, flood: Flood = Flood()) -> list[str]:
    """The simulator's command-line options for a misbehaving peer."""
    args = ["--drop", str(faults.drop)] if faults.drop else []
    if flood.rate:
        args += ["--flood", f"{flood.rate!r}:{flood.content}", "--flood-port", str(flood.port)]
    if quirks.frozen_setpoint:
        args.append("--frozen-setpoint")
    if quirks.drift_axis:
        args += ["--drift", f"A{quirks.drift_axis}:{quirks.drift_deg!r}"]
    if quirks.root_attribute != "Type":
        args += ["--root-attribute", quirks.root_attribute]
    if quirks.ipoc_step is not None:
        args += ["--ipoc-step", str(quirks.ipoc_step)]
    return args


class SimulatedController:
    """One simulated KR C4 of ``spec``, sending from the link's address to the back end's loop."""

    def __init__(self, spec: SimulatorSpec, config: RsiConfig, roles: RsiRoles, link: RobotLink, events: LoopEvents, name: str) -> None:
        self.spec = spec
        self.config = config
        self.roles = roles
        self.link = link
        self.events = events
        self.name = name
        #: The simulator's thread, when it runs in this process (``spec.runner == "thread"``), once started.
        self.thread: SimulatorThread | None = None
        self._process: subprocess.Popen[str] | None = None
        self._summary: dict[str, object] | None = None
        self._clock_loop: asyncio.AbstractEventLoop | None = None

    def start(self, address: tuple[str, int]) -> None:
        """Start the controller, sending to the loop at ``address``."""
        spec = self.spec
        if spec.runner == "thread":
            clock = None
            if not spec.accelerated:
                # The simulated controller keeps wall time whatever clock the application runs on.
                self._clock_loop = asyncio.new_event_loop()
                clock = real_clock().bind(self._clock_loop)
            self.thread = SimulatorThread(
                self.config, address, context=spec.context, roles=self.roles, faults=spec.faults, clock=clock,
                bind=(self.link.host, self.link.port or 0), quirks=spec.quirks, flood=spec.flood,
            ).start()
            return
        self._process = subprocess.Popen(self.command(address), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, bufsize=1)
        assert self._process.stdout is not None
        self.events.watch(self._process.stdout.fileno(), self._on_output)

    def command(self, address: tuple[str, int]) -> list[str]:
        """The command line of the simulated controller's own process, sending to the loop at ``address``."""
        spec = self.spec
        ctx = spec.context
        args = [
            sys.executable, "-m", "robot_bridges.kuka_rsi.simulator", "--to", f"{address[0]}:{address[1]}",
            "--bind", f"{self.link.host}:{self.link.port or 0}", "--cycle", str(ctx.cycle_ms), "--timeout", str(ctx.timeout),
            "--mode", ctx.correction_mode, "--seed", str(spec.faults.seed), "--axis-monitor", str(ctx.axis_monitor_deg[0]),
            "--rt-priority", str(spec.rt_priority),
        ]
        args += quirk_arguments(spec.faults, spec.quirks, spec.flood)
        if spec.peer != "kr-c4":
            args += ["--peer", spec.peer]
        if self.link.config is not None:
            args += ["--config", self.link.config.source]
        return args

    def _on_output(self) -> None:
        assert self._process is not None and self._process.stdout is not None
        line = self._process.stdout.readline()
        if not line:
            self.events.unwatch(self._process.stdout.fileno())
            return
        if line.startswith("{"):
            try:
                self._summary = json.loads(line)
            except json.JSONDecodeError:
                pass
        elif line.strip():
            log.info("%s: %s", self.name, line.strip()[:500])  # the banner: address, cycle, real-time priority
        self.events.changed.set()

    def stop_reason(self) -> str | None:
        """Why the controller stopped (None: it has not)."""
        if self.thread is not None:
            return self.thread.stop_reason
        if self._summary is not None:
            return str(self._summary.get("stopped") or "the simulator ended")
        if self._process is not None and self._process.poll() is not None:
            return f"the simulator exited with code {self._process.returncode}"
        return None

    def close(self) -> None:
        """End the controller: the thread stopped, or the process terminated (killed after 5 s)."""
        if self.thread is not None:
            self.thread.stop()
            self.thread = None
        if self._clock_loop is not None:
            self._clock_loop.close()
            self._clock_loop = None
        if self._process is not None:
            if self._process.poll() is None:
                self._process.terminate()  # our own child, by its handle
            try:
                self._process.communicate(timeout=5)
            except subprocess.TimeoutExpired:
                self._process.kill()
                self._process.communicate()
            self._process = None
