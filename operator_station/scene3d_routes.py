"""The 3D view's routes: ``GET /api/scene3d`` (the robots, the cell, the placed findings) and
``GET /api/scene3d/events?from=N`` (the goals and located frames of the run from the N-th on), and
``GET /api/scene3d/joints?from=N`` (a replayed recording's joint states from the N-th on; a live run's are the feed's).

A station that has run nothing yet shows the robot and cell of the application it was started with; a
replayed trace, which names neither, the robot whose joints its records report.  Bad input is one line
and a 400, as every route of the station answers it.
"""
from __future__ import annotations

import asyncio
import threading
from pathlib import Path
from typing import Any

import orjson
from starlette.requests import Request
from starlette.responses import Response
from starlette.routing import Route

from core_functions.robots import ROBOTS, RobotModel
from execution_engine.app_model.document import read_document
from operator_station.feed import Feed
from operator_station.scene3d import SceneLog, head_scene, scene_log
from operator_station.scene3d_findings import run_finding

#: The largest ``from`` asked (a run keeps far fewer events).
MAX_FROM = 1 << 40


def _json(content: Any, status: int = 200) -> Response:
    return Response(orjson.dumps(content), status_code=status, media_type="application/json")


def event_start(text: str | None) -> int:
    """The ``from`` of an events or joints request: a whole number, 0 when not given (ValueError, one line)."""
    if text in (None, ""):
        return 0
    try:
        value = int(text)
    except ValueError:
        raise ValueError(f"from must be a whole number of events, got {text[:40]!r}") from None
    if not 0 <= value <= MAX_FROM:
        raise ValueError(f"from must be in [0, {MAX_FROM}], got {value}")
    return value


def robot_by_joints(names: list[str]) -> RobotModel | None:
    """The robot whose joints a trace's records name (a trace names no robot)."""
    known = set(names)
    return next((r for r in ROBOTS if known and known <= set(r.joint_names)), None)


class SceneAnswers:
    """What the routes answer for one station: its feed's scene, the idle scene of its start file, the findings."""

    def __init__(self, feed: Feed, app_path: Path | None) -> None:
        self.feed = feed
        self.app_path = app_path
        self._lock = threading.Lock()
        # run, records read, the run's findings
        self._findings: tuple[int, int, list[dict[str, Any]]] = (-1, 0, [])

    def scene(self) -> dict[str, Any]:
        log = scene_log(self.feed)
        snapshot = self.feed.snapshot
        if log.run != snapshot.run:  # nothing began this run's scene: the start file's, or the trace's robot
            self._fallback(log, snapshot.run, snapshot.mode, list(snapshot.joint_names))
        answer = log.static()
        if answer["dry_run"] is not None:  # its findings are in the answer's findings, once
            answer["dry_run"] = {k: v for k, v in answer["dry_run"].items() if k != "findings"}
        answer.update(ok=True, mode=snapshot.mode, findings=self.findings())
        return answer

    def _fallback(self, log: SceneLog, run: int, mode: str, joint_names: list[str]) -> None:
        robot, cell, notes = None, None, []
        if mode == "idle" and self.app_path is not None:
            doc, problems = read_document(self.app_path)
            if doc is None:
                notes = [str(problems[0])] if problems else []
            else:
                robot, cell, notes = head_scene(doc.robot, (self.app_path.parent / doc.cell).resolve() if doc.cell else None)
        elif mode == "replay":
            robot = robot_by_joints(joint_names)
        log.begin(run, robot, cell)
        log.notes.extend(notes)

    def findings(self) -> list[dict[str, Any]]:
        """The dry run's placed findings (kept with the scene from its report, :func:`keep_dry_run`) and the run's
        collision faults (from its error records, each record read once)."""
        snapshot = self.feed.snapshot
        dry_run = scene_log(self.feed).static()["dry_run"]
        dry = list(dry_run.get("findings", [])) if dry_run is not None else []
        with self._lock:
            run, seen, found = self._findings
            if run != snapshot.run:
                seen, found = 0, []
            new = self.feed.records[seen:]  # a slice of the list the run appends to (a new run gets a new list)
            found = list(found)
            known = {_same(f) for f in found}
            for record in new:  # one fault is reported by each group it stops (and the engine): placed once
                f = run_finding(record) if isinstance(record, dict) and record.get("event") == "error" else None
                if f is not None and _same(f) not in known:
                    known.add(_same(f))
                    found.append(f)
            self._findings = (snapshot.run, seen + len(new), found)
            return dry + found


def _same(finding: dict[str, Any]) -> tuple[Any, ...]:
    """What makes two placed findings of a run the same: when, what kind, which bodies or target."""
    return (finding["t"], finding["kind"], tuple(b["name"] for b in finding.get("bodies", ())), tuple(finding.get("target") or ()))


def routes(station: Any) -> list[Route]:
    """The 3D view's routes for ``station`` (:class:`operator_station.server.Station`)."""
    answers = SceneAnswers(station.feed, station.app_path)

    async def scene(request: Request) -> Response:
        return _json(await asyncio.to_thread(answers.scene))

    async def events(request: Request) -> Response:
        try:
            start = event_start(request.query_params.get("from"))
        except ValueError as error:
            return _json({"ok": False, "error": str(error)}, 400)
        run, batch, total = scene_log(station.feed).read(start)
        return _json({"ok": True, "run": run, "from": start, "events": batch, "total": total})

    async def joints(request: Request) -> Response:
        try:
            start = event_start(request.query_params.get("from"))
        except ValueError as error:
            return _json({"ok": False, "error": str(error)}, 400)
        run, names, batch, total = scene_log(station.feed).read_joints(start)
        return _json({"ok": True, "run": run, "from": start, "names": names, "samples": batch, "total": total})

    return [Route("/api/scene3d", scene), Route("/api/scene3d/events", events), Route("/api/scene3d/joints", joints)]

