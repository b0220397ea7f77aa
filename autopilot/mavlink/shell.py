"""The MAVLink shell: ``SERIAL_CONTROL`` on device ``SERIAL_CONTROL_DEV_SHELL`` (10), as PX4 answers it.

QGC's MAVLink Console, MAVSDK's Shell plugin and PX4's ``Tools/mavlink_shell.py`` send what is
typed as ``SERIAL_CONTROL(device 10, flags RESPOND [| EXCLUSIVE], count, data[70])``; the vehicle
answers with its console's output as ``SERIAL_CONTROL(device 10, flags REPLY, timeout 0,
baudrate 0, count, data)``, at most 70 bytes each, in order, to the station that typed it. As
PX4's shell over MAVLink:

* a station's console starts with its first message: a greeting, then the prompt ``nsh> `` (a
  flight controller's NuttX shell; PX4 SITL's own says ``pxh> ``);
* typed characters are echoed; ``\\n`` runs the line (:class:`~.console.Console`), its output
  follows, then the prompt; backspace (0x08, 0x7f) erases the last character; ``\\r`` and other
  control characters are dropped (``\\r\\n`` is one Enter), as are bytes outside ASCII;
* a message without ``RESPOND`` means the station no longer reads (PX4 closes its shell then):
  its lines still run, nothing is sent back, and the console closes unless a line is still
  being typed (MAVSDK sends a long command's first 70-byte pieces without ``RESPOND``);
* a message flagged ``REPLY`` (a vehicle's answer), for another device or another vehicle, or
  with ``count`` above 70, is ignored, as PX4 ignores it.

Bounded whatever is typed: a line keeps at most :data:`LINE_MAX` characters; the output waiting
to be sent at most :data:`OUTPUT_MAX` bytes (the rest of a long output is cut, and said so), and
while more than half of that waits, a new line is not run ("busy"); output is paced at
:data:`MESSAGES_PER_S` per link; a link keeps :data:`MAX_CONSOLES_PER_LINK` consoles, the one
heard from longest ago making room.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field

from quadcommon import wire

from .codec import Encoder
from .codec import mavlink as m
from .console import Console
from .links import Address, GcsLink, SendAllowance
from .params import payload_bytes

PROMPT = b"nsh> "
DATA_LEN = 70  # SERIAL_CONTROL.data
LINE_MAX = 256  # characters of a line kept (the rest is dropped as typed)
OUTPUT_MAX = 32 * 1024  # bytes of output waiting to be sent, at most
MESSAGES_PER_S = 500  # output messages per link and second of the caller's clock (35 kB/s)
MESSAGES_AT_ONCE = 10
MAX_CONSOLES_PER_LINK = 4
_TARGET = 79  # SERIAL_CONTROL's target_system, target_component (extension fields) in the payload
BACKSPACE = (0x08, 0x7F)
CUT = b"\n[output cut: too much at once]\n"


@dataclass
class _Terminal:
    """One station's console: what is being typed and what waits to be sent."""

    address: Address
    line: bytearray = field(default_factory=bytearray)
    output: bytearray = field(default_factory=bytearray)
    cut: bool = False  # output was cut since the backlog last emptied


class MavlinkShell:
    """PX4's MAVLink shell (module docstring) over a :class:`~.console.Console`: a terminal per station on
    each link, its output paced as SERIAL_CONTROL replies."""

    def __init__(
        self,
        console: Console,
        encoder: Encoder,
        links: list[GcsLink],
        system_id: int,
        clock: Callable[[], float],
        greeting: str,
    ) -> None:
        self.console = console
        self.encoder = encoder
        self.links = links
        self.system_id = system_id
        self.greeting = greeting.encode("ascii", "replace")
        self.terminals: list[OrderedDict[Address, _Terminal]] = [OrderedDict() for _ in links]
        self.allowance = [SendAllowance(MESSAGES_PER_S, MESSAGES_AT_ONCE, clock) for _ in links]
        self.lines_run = 0
        self.lines_refused = 0  # busy: the backlog was full
        self._waiting = False  # output may be waiting: pump() has work

    def register(self, dispatcher) -> None:
        """Put :meth:`on_message` in the dispatcher's table for SERIAL_CONTROL."""
        dispatcher[m.MAVLINK_MSG_ID_SERIAL_CONTROL] = self.on_message

    # -- input ----------------------------------------------------------------------------------
    def on_message(self, msg, link: GcsLink, address: Address) -> None:
        """One SERIAL_CONTROL: a shell message for this vehicle is typed into its station's terminal (opened,
        with the greeting and prompt, on its first message); any other is ignored."""
        if msg.device != m.SERIAL_CONTROL_DEV_SHELL or msg.flags & m.SERIAL_CONTROL_FLAG_REPLY:
            return
        if msg.count > DATA_LEN or not self._for_us(msg):
            return
        terminals = self.terminals[link.index]
        terminal = terminals.get(address)
        if terminal is None:
            if len(terminals) >= MAX_CONSOLES_PER_LINK:
                terminals.popitem(last=False)
            terminal = terminals[address] = _Terminal(address)
            self._emit(terminal, self.greeting + PROMPT)
        else:
            terminals.move_to_end(address)
        for byte in bytes(msg.data[: msg.count]):
            self._typed(terminal, byte)
        if not msg.flags & m.SERIAL_CONTROL_FLAG_RESPOND:  # the station no longer reads
            terminal.output.clear()
            if not terminal.line:
                del terminals[address]

    def _for_us(self, msg) -> bool:
        """PX4 serves a SERIAL_CONTROL addressed to it or to all (the target fields, a MAVLink 2
        extension, are absent from older senders' messages: to all)."""
        payload = payload_bytes(msg)
        if len(payload) <= _TARGET:
            return True
        target_component = payload[_TARGET + 1] if len(payload) > _TARGET + 1 else 0
        ours = (0, wire.AUTOPILOT_COMPONENT_ID)
        return payload[_TARGET] in (0, self.system_id) and target_component in ours

    def _typed(self, terminal: _Terminal, byte: int) -> None:
        if byte == 0x0A:  # Enter
            line = terminal.line.decode("ascii")
            terminal.line.clear()
            self._emit(terminal, b"\n")
            self._run(terminal, line)
            self._emit(terminal, PROMPT)
        elif byte in BACKSPACE:
            if terminal.line:
                terminal.line.pop()
                self._emit(terminal, b"\b \b")
        elif (byte == 0x09 or 0x20 <= byte < 0x7F) and len(terminal.line) < LINE_MAX:
            terminal.line.append(byte)
            self._emit(terminal, bytes((byte,)))

    def _run(self, terminal: _Terminal, line: str) -> None:
        if not line.strip():
            return
        if len(terminal.output) > OUTPUT_MAX // 2:
            self.lines_refused += 1
            self._emit(terminal, f"nsh: busy (output still being sent), not run: {line[:40]}\n".encode())
            return
        self.lines_run += 1
        self._emit(terminal, self.console.run(line).encode("ascii", "replace"))

    def _emit(self, terminal: _Terminal, data: bytes) -> None:
        self._waiting = True
        room = OUTPUT_MAX - len(terminal.output)
        if len(data) <= room:
            terminal.output += data
        elif not terminal.cut:
            terminal.cut = True
            terminal.output += data[: max(room - len(CUT), 0)] + CUT[: room]

    # -- output ---------------------------------------------------------------------------------
    def pump(self, budget: int) -> None:
        """Send waiting output, at most ``budget`` messages per link (consoles taking turns) and
        no more than :data:`MESSAGES_PER_S` of the clock allows."""
        if not self._waiting:  # (every frame asks)
            return
        self._waiting = False
        for link, terminals, allowance in zip(self.links, self.terminals, self.allowance, strict=True):
            waiting = [t for t in terminals.values() if t.output]
            if not waiting:
                continue
            left = allowance.take(budget)
            while left > 0 and waiting:
                for terminal in waiting:
                    if left > 0 and terminal.output:
                        self._send(link, terminal)
                        left -= 1
                waiting = [t for t in waiting if t.output]
            allowance.give_back(left)
            self._waiting = self._waiting or bool(waiting)

    def _send(self, link: GcsLink, terminal: _Terminal) -> None:
        chunk = bytes(terminal.output[:DATA_LEN])
        del terminal.output[:DATA_LEN]
        if not terminal.output:
            terminal.cut = False
        msg = m.MAVLink_serial_control_message(m.SERIAL_CONTROL_DEV_SHELL, m.SERIAL_CONTROL_FLAG_REPLY, 0, 0,
                                               len(chunk), list(chunk.ljust(DATA_LEN, b"\0")))  # fmt: skip
        link.send_to(self.encoder.pack(msg), terminal.address)
