"""RivetInstallation: the skills of the paper's demonstrator (Herrero 2017, section 3.1, Figure 10).

Three skills, each a sequence of primitives: deburring a drilled hole (left arm, deburring
tool), picking a rivet from a tray (right arm, gripper) and inserting it into the hole.  Hole
positions come from the cell model (the CAD-derived fixture information) and are corrected by
the wrist camera before any contact, because the nominal positions are only good to a few
tenths of a millimetre and the process needs 0.2 mm.

Conventions of the cell model these skills rely on: a hole frame sits on the part's surface
with z pointing into the hole; a rivet slot frame sits on top of the rivet head with z pointing
down the rivet; a rivet element (reference, e.g. ``ref_R10``) gives ``diameter``, ``length``
and ``grip_depth`` (how far below the head top the fingers close), in metres.
"""
from __future__ import annotations

from core_functions.catalog import VISION_OUTCOMES, Hold, ParamSpec, ParamType, skill
from core_functions.functions import CoreFunctions, Skill, SkillContext
from core_functions.geometry import Pose
from core_functions.primitives import Dwell, EndEffector, MoveCartesian, SetSpeed

#: Distance above a hole or slot where every skill starts and ends (m).
CLEARANCE = 0.05
#: Stand-off for the final vision-guided approach before contact (m).
STANDOFF = 0.01
#: Speed fraction of process moves in contact with the part.
PROCESS_SPEED = 0.1
#: How long the deburring tool works the hole edge (s).
DEBURR_TIME = 0.8
#: Allowed difference between rivet and hole diameters (m).
DIAMETER_TOLERANCE = 0.0002
#: How far an arm of a dual-arm robot moves aside, towards its own side, when it leaves a hole (m):
#: the other arm works on the same hole next, and two hands do not fit above one hole.
PARK_ASIDE = 0.10
#: ... and at least this far from the robot's middle plane (y = 0, m), out of a zone around the part.
PARK_Y = 0.14


class RivetInstallation(CoreFunctions):
    """Skills for installing rivets in drilled holes of an aeronautical part."""

    def __init__(self, context: SkillContext) -> None:
        super().__init__(context)
        #: The rivet reference in the gripper (set by pick_rivet, cleared by insert_rivet).
        self.held_rivet: str | None = None

    def _leave(self, above: Pose, frame: str) -> Skill:
        """Leave a hole: straight up to ``above``, then aside towards the arm's own side (a dual-arm robot's
        other arm works on this hole next); a single arm stays above it."""
        yield MoveCartesian(above, "linear", frame=f"{frame} clearance")
        side = {"left_arm": 1.0, "right_arm": -1.0}.get(self.ctx.group, 0.0)
        if side:
            aside = side * max(side * above.y + PARK_ASIDE, PARK_Y)
            yield MoveCartesian(above.translated(dy=aside - above.y), "ptp", frame=f"{frame} aside")

    def _process(self, *moves: MoveCartesian) -> Skill:
        """Run contact moves slowly, then restore full speed for the free moves that follow."""
        yield SetSpeed(PROCESS_SPEED)
        for move in moves:
            yield move
        yield SetSpeed(1.0)

    @skill(
        ParamSpec("hole", ParamType.FRAME, "the drilled hole to debur", kinds=("hole",)),
        states=("Motion", "Vision", "EndEffector"),
        outcomes=VISION_OUTCOMES,
    )
    def debur_drilling(self, hole: str) -> Skill:
        """Detect a drilled hole with the wrist camera and debur its edge with the deburring tool."""
        yield MoveCartesian(self.cell.pose(hole).offset_local(dz=-CLEARANCE), "ptp", frame=f"{hole} clearance")
        yield from self.locate_frame(hole)
        found = self.cell.pose(hole)
        yield MoveCartesian(found.offset_local(dz=-STANDOFF), "linear", frame=f"{hole} stand-off")
        yield EndEffector("tool_on")
        yield from self._process(MoveCartesian(found, "linear", frame=hole))
        yield Dwell(DEBURR_TIME)
        yield MoveCartesian(found.offset_local(dz=-STANDOFF), "linear", frame=f"{hole} stand-off")
        yield EndEffector("tool_off")
        yield from self._leave(found.offset_local(dz=-CLEARANCE), hole)

    @skill(
        ParamSpec("rivet", ParamType.FRAME, "the tray slot holding the rivet", kinds=("rivet_slot",)),
        ParamSpec("reference", ParamType.ELEMENT, "the rivet reference (its diameter, length and grip depth)", kinds=("rivet",)),
        states=("Motion", "EndEffector"),
        requires=Hold.NOTHING,
        leaves=Hold.PART,
    )
    def pick_rivet(self, rivet: str, reference: str) -> Skill:
        """Pick a rivet from its tray slot with the gripper and extract it from the tray."""
        grip_depth = self.cell.number(reference, "grip_depth", 0.004)
        length = self.cell.number(reference, "length")
        slot = self.cell.pose(rivet)
        yield EndEffector("gripper_open")
        yield MoveCartesian(slot.offset_local(dz=-CLEARANCE), "ptp", frame=f"{rivet} clearance")
        yield from self._process(MoveCartesian(slot.offset_local(dz=grip_depth), "linear", frame=f"{rivet} grasp"))
        yield EndEffector("gripper_close")
        self.held_rivet = reference
        # Extract straight up past the rivet's own length before any sideways move.
        yield MoveCartesian(slot.offset_local(dz=-max(CLEARANCE, length + STANDOFF)), "linear", frame=f"{rivet} extracted")

    @skill(
        ParamSpec("hole", ParamType.FRAME, "the hole to insert the held rivet into", kinds=("hole",)),
        states=("Motion", "Vision", "EndEffector"),
        requires=Hold.PART,
        leaves=Hold.NOTHING,
        outcomes=VISION_OUTCOMES,
    )
    def insert_rivet(self, hole: str) -> Skill:
        """Insert the held rivet into a hole: vision-corrected approach, slow insertion, release, retract."""
        if self.held_rivet is not None:
            rivet_d = self.cell.number(self.held_rivet, "diameter")
            hole_d = self.cell.number(hole, "diameter", rivet_d)
            if abs(rivet_d - hole_d) > DIAMETER_TOLERANCE:
                raise ValueError(
                    f"rivet {self.held_rivet} ({rivet_d * 1000:.2f} mm) does not fit {hole} ({hole_d * 1000:.2f} mm)"
                )
            length = self.cell.number(self.held_rivet, "length")
            grip_depth = self.cell.number(self.held_rivet, "grip_depth", 0.004)
        else:  # a rivet put in the hand by other means: insert by the hole alone
            length, grip_depth = 0.0, 0.0
        yield MoveCartesian(self.cell.pose(hole).offset_local(dz=-CLEARANCE - length), "ptp", frame=f"{hole} clearance")
        yield from self.locate_frame(hole)
        found = self.cell.pose(hole)
        tip_above = found.offset_local(dz=-(length - grip_depth) - STANDOFF)
        yield MoveCartesian(tip_above, "linear", frame=f"{hole} rivet above")
        yield from self._process(MoveCartesian(found.offset_local(dz=-grip_depth), "linear", frame=f"{hole} inserted"))
        yield EndEffector("gripper_open")
        self.held_rivet = None
        yield from self._leave(found.offset_local(dz=-CLEARANCE), hole)
