"""COMMAND_LONG / COMMAND_INT handling: every command gets a COMMAND_ACK, never silence.

Handlers are registered per MAV_CMD id and return ``(MAV_RESULT, reason)``; an unknown command is
answered ``MAV_RESULT_UNSUPPORTED``. Handlers live with the code that owns the behaviour
(the core wires the vehicle's commands, :mod:`.vehicle_commands`, and the mission and parameter
services' here); a command is
registered only if :data:`~.validation.COMMAND_RULES` lists it, the one table of what each handled
command's parameters may be and which of its slots it uses.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

from .codec import mavlink
from .validation import COMMAND_RULES


class CommandRequest(NamedTuple):
    """One MAV_CMD as its handler reads it, from COMMAND_LONG or COMMAND_INT (or the console)."""

    command: int
    params: tuple[float, float, float, float, float, float, float]  # param1..7 (COMMAND_INT x, y scaled back)
    frame: int | None  # COMMAND_INT frame, None for COMMAND_LONG
    source_system: int
    source_component: int
    link: object  # the GCS link the command came on (to answer there)
    address: tuple[str, int]


Handler = Callable[[CommandRequest], tuple[int, str]]


def request_from_message(msg, link, address) -> CommandRequest:
    """A COMMAND_LONG or COMMAND_INT as a CommandRequest (COMMAND_INT x/y stay integers)."""
    if msg.get_msgId() == mavlink.MAVLINK_MSG_ID_COMMAND_INT:
        params = (msg.param1, msg.param2, msg.param3, msg.param4, float(msg.x), float(msg.y), msg.z)
        frame = msg.frame
    else:
        params = (
            msg.param1,
            msg.param2,
            msg.param3,
            msg.param4,
            msg.param5,
            msg.param6,
            msg.param7,
        )
        frame = None
    return CommandRequest(
        msg.command, params, frame, msg.get_srcSystem(), msg.get_srcComponent(), link, address
    )


class CommandDispatcher:
    """The MAV_CMD handlers by command id (module docstring)."""

    def __init__(self) -> None:
        self.handlers: dict[int, Handler] = {}

    def register(self, command: int, handler: Handler) -> None:
        """``handler`` answers MAV_CMD ``command``; ValueError if :data:`~.validation.COMMAND_RULES`
        has no rules for it."""
        if command not in COMMAND_RULES:  # a programming error: found when the autopilot starts
            raise ValueError(f"MAV_CMD {command} is not in validation.COMMAND_RULES: add its rules there")
        self.handlers[command] = handler

    def dispatch(self, request: CommandRequest) -> tuple[int, str]:
        """(MAV_RESULT, reason) of ``request``: UNSUPPORTED without a handler, FAILED when the
        handler raises (never an exception, never silence)."""
        handler = self.handlers.get(request.command)
        if handler is None:
            return mavlink.MAV_RESULT_UNSUPPORTED, f"command {request.command} not supported"
        try:
            return handler(request)
        except Exception as exc:  # a bug in a handler must not kill the autopilot or go silent
            return mavlink.MAV_RESULT_FAILED, f"command {request.command} failed: {exc}"


def command_ack(request: CommandRequest, result: int):
    """The COMMAND_ACK answering ``request`` with ``result`` (MAV_RESULT), addressed to its sender."""
    return mavlink.MAVLink_command_ack_message(
        request.command, result, 0, 0, request.source_system, request.source_component
    )
