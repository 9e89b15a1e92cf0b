"""The simulated hand I/O of one Nextage arm: gripper, air, deburring tool, air hand.

On the real robot every hand function is a digital output (NextageClient's ``handtool_*``,
``airhand_*_drawin/keep/release``, gripper open/close); what a skill sees is the output state and
that the action takes a moment (a valve switching, a gripper closing, a spindle spinning up).
The simulator keeps the same state and charges a fixed, realistic time per action.
"""
from __future__ import annotations

from dataclasses import dataclass, field

#: Outputs of one hand, in the order results report them.
IO_NAMES: tuple[str, ...] = ("gripper_closed", "air", "tool", "hand_draw_in", "hand_release")


@dataclass(frozen=True)
class HandAction:
    """What an action sets and how long the hardware takes to do it (s)."""

    outputs: dict[str, bool]
    duration: float


ACTIONS: dict[str, HandAction] = {
    "gripper_open": HandAction({"gripper_closed": False}, 0.5),
    "gripper_close": HandAction({"gripper_closed": True}, 0.5),
    "air_on": HandAction({"air": True}, 0.1),
    "air_off": HandAction({"air": False}, 0.1),
    "tool_on": HandAction({"tool": True}, 0.8),  # the deburring spindle spins up
    "tool_off": HandAction({"tool": False}, 0.5),  # ... and runs down
    # Nextage air hand: draw in (suction), keep (both valves closed), release (blow off)
    "hand_draw_in": HandAction({"hand_draw_in": True, "hand_release": False}, 0.3),
    "hand_keep": HandAction({"hand_draw_in": False, "hand_release": False}, 0.05),
    "hand_release": HandAction({"hand_draw_in": False, "hand_release": True}, 0.3),
}


@dataclass
class HandIO:
    """Output state of one hand; all off at power-up (gripper open)."""

    state: dict[str, bool] = field(default_factory=lambda: dict.fromkeys(IO_NAMES, False))

    def apply(self, action: str) -> HandAction:
        """Switch the outputs of ``action`` and return it (with its duration); KeyError if unknown."""
        spec = ACTIONS[action]
        self.state.update(spec.outputs)
        return spec

    def snapshot(self) -> dict[str, bool]:
        return dict(self.state)
