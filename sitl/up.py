"""``quadsitl up``: simulator + autopilot per vehicle as two OS processes, linked, in the foreground.

Every port of every instance is checked first (:func:`sitl.launcher.check_launch`: a port in use,
or two instances whose ports overlap, is an error naming the port, the roles and both instances;
exit 2, nothing started); the processes start through the one launcher (:mod:`sitl.launcher`),
which waits until each simulator reports its autopilot linked; the endpoints a ground station
connects to and the restart policy are printed. A process that dies is handled by the
supervisor (:mod:`sitl.supervise`): the survivor keeps running so that its failsafe acts, the loss
is reported, and the lost process is restarted (unless ``--no-restart``; capped). A simulator
that reaches ``--duration`` ends its vehicle's run normally. Ctrl-C or SIGTERM stops everything
(SIGTERM, then SIGKILL after a grace period). Children die with the launcher in any case
(PR_SET_PDEATHSIG).

Exit status: 0 after Ctrl-C / SIGTERM or the end of ``--duration`` with every process there;
1 when a process was lost and is still down at the end (or nothing was left running); 2 when it
could not start.
"""

from __future__ import annotations

from collections.abc import Sequence

from quadcommon import wire

from .launcher import Launcher, LaunchError, VehicleSpec, port_notes
from .supervise import RestartPolicy, Supervisor, stop_on_signals, write_line
from .view_process import check_view_port, start_view

__all__ = ["LaunchError", "RestartPolicy", "VehicleSpec", "endpoints_banner", "run_up"]
POLL_S = 0.1  # the foreground loop's period (wall): reaction time to a lost process and to Ctrl-C


def endpoints_banner(spec: VehicleSpec, ports: wire.Ports) -> str:
    """What a user points their tools at: the GCS client port (every vehicle's, told apart by
    system id) and the API endpoint of this vehicle alone (:func:`quadcommon.wire.api_endpoint`)."""
    n = spec.instance
    speed = f"{spec.speed}{'x' if spec.speed != 'max' else ''}"
    kind, api_port = wire.api_endpoint(ports, n)
    return "\n".join(
        [
            f"quadsitl: vehicle {n} is up (MAVLink sysid {wire.system_id(n)}, controller {spec.controller}, "
            f"scenario {spec.scenario}, speed {speed})",
            f"  QGroundControl / MAVProxy : udp {ports.gcs_remote}   "
            f"(mavproxy.py --master=udpin:127.0.0.1:{ports.gcs_remote})",
            f"  MAVSDK / API scripts      : {wire.api_connect_url(ports, n)}   "
            f"(pymavlink: {kind}:127.0.0.1:{api_port})",
            f"  zenoh (truth, internals)  : tcp/127.0.0.1:{ports.zenoh}   "
            f"keys quadsitl/{n}/truth, quadsitl/{n}/controller",
            f"  flight logs (ULog)        : {_log_line(spec)}",
        ]
    )


def _log_line(spec: VehicleSpec) -> str:
    if spec.log_dir is None:
        return "off (--no-log)"
    return (f"{spec.log_dir}/YYYY-MM-DD/HH_MM_SS.ulg, from arming to disarming (SDLOG_MODE); "
            "MAVLink log download")  # fmt: skip


def _echo(name: str, line: str) -> None:
    write_line(f"[{name}] {line}")


def compile_first(specs: Sequence[VehicleSpec]) -> None:
    """Compile what the vehicles' processes would compile at their start (once after an install or
    an edited equation: seconds per entry, and the link would wait on it), with a word about it."""
    from .compile import compile_all, missing, targets

    todo = missing(targets(sorted({s.controller for s in specs}), campaign=False))
    if todo:
        write_line(f"quadsitl: compiling the flight's kernels first ({', '.join(todo)}): once after an "
                   "install or an edit, cached after that")  # fmt: skip
        compile_all(todo, log=lambda line: write_line(f"quadsitl:{line}"))


def run_up(
    specs: Sequence[VehicleSpec], policy: RestartPolicy | None = None, view_port: int | None = None
) -> int:
    """Foreground ``quadsitl up``: until Ctrl-C / SIGTERM, the end of ``--duration`` or nothing left.

    ``view_port``: also start the live view (``--view``) on 127.0.0.1:``view_port`` once the
    vehicles are linked (:mod:`sitl.view_process`), print its URL and stop it with the rest.
    """
    policy = RestartPolicy() if policy is None else policy
    stop = stop_on_signals()
    launcher = Launcher(echo=_echo)
    view_url = None
    try:
        if view_port is not None:  # --view: its port is checked with the others, before any start
            check_view_port(view_port)
        compile_first(specs)
        launcher.start_vehicles(specs)
        if view_port is not None:
            _, view_url = start_view(launcher, [s.instance for s in specs], view_port, specs[0].sitl_config)
    except LaunchError as exc:
        write_line(f"quadsitl: {exc}", error=True)
        launcher.stop()
        return 2
    for note in port_notes(specs):
        write_line(f"quadsitl: {note}", error=True)
    banner = [endpoints_banner(spec, launcher.ports[spec.instance]) for spec in specs]
    if view_url is not None:
        banner.append(f"  live view (browser)       : {view_url}")
    write_line("\n".join([*banner, policy.describe(), "  Ctrl-C stops every process."]))
    supervisor = Supervisor(launcher, specs, policy)
    try:
        while not stop.wait(POLL_S):
            supervisor.poll()
            if not supervisor.active:  # every run over (--duration), or nothing left to restart
                break
    finally:
        write_line("quadsitl: stopping ...")
        launcher.stop()
        write_line("quadsitl: stopped")
    return 0 if supervisor.whole else 1
