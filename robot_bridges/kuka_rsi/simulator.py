"""A KR C4 controller running an RSI context, as seen from the network: the other end of the bridge.

What it reproduces, because the bridge must cope with it (seed 003; ARCHITECTURE "Protocol facts"):

* a ``<Rob>`` packet every cycle (4 ms or 12 ms) on a fixed clock, whether or not replies come;
  IPOC steps by the cycle in ms;
* a reply counts only if it parses, carries the configured SENTYPE and the packet's IPOC, and
  arrives before the next cycle; otherwise the packet is *late*: ``Delay`` counts it, each
  RECEIVE value keeps its last value (HOLDON=1) or falls to zero (HOLDON=0), and after
  ``timeout`` late packets in a row RSI stops with a timeout error;
* axis corrections (``AK``, deg) and Cartesian corrections (``RKorr``, mm/deg in the base
  frame, rotations about the TCP), absolute (relative to the pose where RSI_MOVECORR began) or
  relative (increments per cycle); each clamped like an AXISCORR / POSCORR object and its
  total watched like AXISCORRMON / POSCORRMON, which stop the robot when exceeded;
* software limit switches and the axes' maximum speeds: a set point beyond either stops RSI;
* a servo that follows the set point (``ASPos``) with a first-order lag (``AIPos``);
* the KRL program of ITRA's handshakes: allow start -> task active, allow move ->
  RSI_MOVECORR (corrections followed), request end -> RSI_MOVECORR left, allow finish -> the task
  ends and RSI stops; ``Stop`` ends RSI at once;
* injected faults for tests: send jitter, lost packets, garbage datagrams, replies dropped;
* peers that report what they like (:class:`Quirks`), as the external system meets them: a set
  point frozen at the start pose (ROS-Industrial's ``kuka_rsi_simulator`` never updates ``ASPos``),
  a reported set point drifting away from the real one, ``<Rob TYPE="KUKA">`` (ROS-I's spelling),
  an IPOC counting packets instead of milliseconds;
* a second sender on the controller's host (:class:`~.spoofer.Flood`): forged packets or garbage
  from another port of the controller's IP, at many times the cycle rate.

:class:`~.krc_model.KrcModel` is the controller without I/O, stepped cycle by cycle; ``sim_network`` puts it
on a UDP socket: :func:`~.sim_network.run_lockstep` (accelerated: the next packet goes out as soon as the reply
is in or known missing; lateness is counted against the simulated cycle, so 100,000 cycles run in seconds and
deterministically) and :func:`~.sim_network.run_realtime` (a fixed clock from the injected
:class:`~node_transport.clock.Clock`); ``sim_faults`` holds what it does wrong on purpose.  This module is
its command line: ``python -m robot_bridges.kuka_rsi.simulator``.
"""
from __future__ import annotations

import argparse
import asyncio
import json
import signal
import socket
import sys
import threading
from collections.abc import Sequence

from core_functions.option_ranges import argument_type
from node_transport.clock import Clock, real_clock, run_with_clock
from robot_bridges.kuka_rsi.config import default_config, load_config
from robot_bridges.kuka_rsi.krc_model import PEERS, KrcModel, RsiContext, RsiStopped, like_peer
from robot_bridges.kuka_rsi.realtime import ask_realtime
from robot_bridges.kuka_rsi.sim_faults import Faults, Quirks
from robot_bridges.kuka_rsi.sim_network import Endpoint, latency_summary, run_lockstep, run_realtime
from robot_bridges.kuka_rsi.spoofer import Flood, Flooder


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m robot_bridges.kuka_rsi.simulator", description=__doc__.split("\n")[0])
    p.add_argument("--config", help="RSI Ethernet configuration XML (default: the package's)")
    p.add_argument("--to", default="", help="external system HOST:PORT (default: IP_NUMBER:PORT of the config)")
    p.add_argument("--bind", default="127.0.0.1:0", help="address the controller sends from (default 127.0.0.1:0)")
    p.add_argument("--cycle", type=argument_type("cycle"), default=4, help="RSI cycle in ms: 4 or 12")
    p.add_argument("--accelerated", action="store_true", help="lockstep: next packet as soon as the reply is in")
    p.add_argument("--speed", type=argument_type("speed"), default=1.0, help="real-time mode: run faster than real time by this factor, in [0.01, 1000]")
    p.add_argument("--cycles", type=argument_type("cycles"), default=None, help="stop after this many cycles, in [1, 1000000000000]")
    p.add_argument("--timeout", type=argument_type("timeout", "kuka-rsi"), default=100, help="late packets in a row that stop RSI, in [1, 100000]")
    p.add_argument("--mode", choices=("absolute", "relative"), default="absolute", help="correction mode")
    p.add_argument("--axis-monitor", type=argument_type("axis_monitor"), default=360.0, help="AXISCORRMON limit (deg, every axis), in [0.001, 360]")
    p.add_argument("--jitter-ms", type=argument_type("jitter_ms"), default=0.0, help="random delay of each packet sent (ms), in [0, 1000]")
    p.add_argument("--loss", type=argument_type("loss"), default=0.0, help="probability a packet sent is lost, in [0, 1]")
    p.add_argument("--garbage", type=argument_type("garbage"), default=0.0, help="probability a packet sent is garbage, in [0, 1]")
    p.add_argument("--drop", type=argument_type("sim_drop", label="drop"), default=0.0, help="probability that a valid reply is discarded (the cycle is late), in [0, 1]")
    p.add_argument("--seed", type=argument_type("seed"), default=0, help="random seed of the faults, in [0, 4294967295]")
    p.add_argument("--frozen-setpoint", action="store_true", help="report ASPos/RSol of the start pose forever (ROS-I's simulator)")
    p.add_argument("--drift", default="", metavar="AXIS:DEG", help="the reported ASPos of AXIS drifts by DEG per cycle, e.g. A3:0.01")
    p.add_argument("--root-attribute", default="Type", help="how <Rob> spells its type attribute (ROS-I's simulator: TYPE)")
    p.add_argument("--ipoc-step", type=argument_type("ipoc_step"), default=None, help="IPOC increment per cycle, in [1, 1000] (default: the cycle in ms; ROS-I's simulator: 1)")
    p.add_argument("--flood", default="", metavar="RATE[:CONTENT]", help="a second sender on the controller's IP, another port: RATE datagrams per cycle of packet (forged, Delay +50), garbage or mixed")
    p.add_argument("--flood-port", type=argument_type("port"), default=0, help="the flooder's port on the controller's IP, in [0, 65535] (default 0: any free one)")
    p.add_argument("--reply-grace", type=argument_type("reply_grace"), default=0.25, help="accelerated mode: wall seconds to wait for a reply, in [0, 60]")
    p.add_argument("--rt-priority", type=argument_type("rt_priority"), default=0, help="try SCHED_FIFO at this priority, in [0, 99] (0: do not; a controller is hard real time)")
    p.add_argument("--peer", choices=PEERS, default="kr-c4", help="behave like this controller at its defaults (ros-industrial: kuka_experimental's kuka_rsi_simulator)")
    p.add_argument("--accept-echo", action="store_true", help="benchmark baseline: a datagram equal to the packet is the reply")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Run the simulator; the last line on stdout is a JSON summary. Exit 0 normal end, 2 RSI error, 1 bad usage."""
    args = _parser().parse_args(argv)
    try:
        config = load_config(args.config) if args.config else default_config()
        to = Endpoint.parse(args.to) if args.to else Endpoint(config.ip, config.port)
        bind = Endpoint.parse(args.bind)
        context = RsiContext(
            cycle_ms=args.cycle, timeout=args.timeout, correction_mode=args.mode, axis_monitor_deg=(args.axis_monitor,) * 6
        )
        faults = Faults(args.jitter_ms, args.loss, args.garbage, args.seed, args.drop)
        axis, deg = Quirks.parse_drift(args.drift) if args.drift else (0, 0.0)
        quirks = Quirks(args.frozen_setpoint, axis, deg, args.root_attribute, args.ipoc_step)
        flood = Flood.parse(args.flood) if args.flood else Flood()
        flood = Flood(flood.rate, flood.content, flood.delay_jump, args.flood_port)
        context, quirks = like_peer(args.peer, context, quirks)
        model = KrcModel(config, context, accept_echo=args.accept_echo, quirks=quirks)
    except (ValueError, OSError) as error:
        print(f"kuka_rsi simulator: {error}", file=sys.stderr)
        return 1
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        sock.bind((bind.host, bind.port))
    except OSError as error:
        print(f"kuka_rsi simulator: cannot bind {bind}: {error.strerror}", file=sys.stderr)
        return 1
    host, port = sock.getsockname()
    peer = (to.host, to.port)
    try:
        flooder = Flooder(flood, host, peer, model, args.seed) if flood.rate > 0 else None
    except OSError as error:
        sock.close()
        print(f"kuka_rsi simulator: cannot bind the flooder to {host}:{flood.port}: {error.strerror}", file=sys.stderr)
        return 1
    priority = ask_realtime(args.rt_priority)
    flooding = "" if flooder is None else f", flooding from {flooder.address[0]}:{flooder.address[1]} ({flood.rate:g} {flood.content} per cycle)"
    print(f"KRC simulator {host}:{port} -> {to}, {args.cycle} ms, {'accelerated' if args.accelerated else f'x{args.speed:g}'}, {priority}{flooding}", flush=True)
    stop = threading.Event()
    # SIGTERM / SIGINT end the run between two cycles, so the summary below is still printed.
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())

    async def realtime(clock: Clock) -> RsiStopped | None:
        return await asyncio.to_thread(run_realtime, sock, peer, model, clock, cycles=args.cycles, faults=faults, stop=stop, flooder=flooder)

    try:
        if args.accelerated:
            result = run_lockstep(sock, peer, model, cycles=args.cycles, faults=faults, reply_grace=args.reply_grace, stop=stop, flooder=flooder)
        else:
            result = run_with_clock(realtime, real_clock() if args.speed == 1.0 else Clock(args.speed))
    finally:
        sock.close()
        if flooder is not None:
            flooder.close()
    s = model.stats
    summary = {
        "stopped": result.reason if result else None,
        "error": bool(result and result.error),
        "packets": s.packets,
        "late": s.late,
        "late_since_first_reply": s.late_since_first_reply,
        "accepted": s.accepted,
        "invalid_replies": s.invalid_replies,
        "dropped": s.dropped,
        "overruns": s.overruns,
        "last_ipoc": model.ipoc,
        "round_trip_us": latency_summary(s.latencies_ns),
        "late_ipocs": s.late_ipocs[:20],
        "late_replies": s.late_replies_discarded,
        "lateness_us": latency_summary(s.lateness_ns),
        "flood_sent": s.flood_sent,
        "flood_replies": s.flood_replies,
    }
    print(json.dumps(summary), flush=True)
    return 2 if result and result.error else 0


if __name__ == "__main__":
    sys.exit(main())
