"""``quadsitl compile``: compile the flight's kernels now, in parallel, instead of at first use.

numba compiles each kernel entry (:mod:`quadcommon.kernel`) the first time a process needs it and
caches it on disk, so after an install, an upgrade or an edited equation the first simulator,
autopilot or campaign of each controller spends seconds compiling (~3-10 s per entry). Here the
entries a flight needs are compiled up front, one process per core: the plant (coupled and
nominal) and the frame encoder's float fields, the sensor models, the estimator, the cascade of
each controller and the campaign engine's flight of each controller on the truth (``--estimate``:
also its flight on the EKF, what a campaign with a ``[estimation]`` section flies, several times
longer to compile). Already cached entries cost a fraction of a second each. ``make test`` runs it
before the suite, so no test's process waits on a compilation.
"""

from __future__ import annotations

import argparse
import os
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor

ESTIMATED_CAMPAIGN = "paper_box_gps"  # a shipped campaign flown on the EKF (what --estimate warms)


def targets(controllers: Sequence[str], campaign: bool = True, estimate: bool = False) -> list[str]:
    """What to compile: ``plant``, ``estimator``, ``sensors``, ``cascade:NAME``, ``campaign:NAME``
    and with ``estimate`` ``campaign-ekf:NAME`` (the campaign's flight on the EKF), the slowest
    first (they are handed out in this order)."""
    out = ["plant", "estimator", "sensors"]
    if campaign and estimate:
        out += [f"campaign-ekf:{name}" for name in controllers]
    if campaign:
        out += [f"campaign:{name}" for name in controllers]
    return out + [f"cascade:{name}" for name in controllers]


def compile_target(target: str) -> tuple[str, float]:
    """Compile (or load) one target's entries in this process; returns its name and seconds."""
    start = time.perf_counter()
    kind, _, name = target.partition(":")
    if kind == "plant":
        from dataclasses import replace

        from quadcommon.config import load_vehicle
        from quadcommon.wire_values import FRAME_ENTRIES, entry
        from simulator.dynamics.nominal_plant import NominalPlant
        from simulator.dynamics.plant import Plant

        vehicle = load_vehicle("paper_quad")
        Plant(vehicle, 0.001)
        NominalPlant(replace(vehicle, plant=replace(vehicle.plant, model="nominal")), 0.001)
        for fn in FRAME_ENTRIES:  # the frame encoder's and decoder's wire values
            entry(fn)
        from simulator.mavlink.hil import delivery_records_entry

        delivery_records_entry()  # the frame's messages from the sensors' delivery
    elif kind == "estimator":
        from autopilot.estimation.eskf import ErrorStateEkf

        ErrorStateEkf()
    elif kind == "sensors":
        from simulator.sensors.models import sensor_entries

        sensor_entries()
    elif kind == "cascade":
        from autopilot.control.cascade import Cascade
        from autopilot.control.config import load_controller
        from quadcommon.config import load_vehicle

        Cascade(load_controller(name), load_vehicle("paper_quad"), 0.002)
    elif kind in ("campaign", "campaign-ekf"):
        from sitl.campaign.batch import warm_up
        from sitl.campaign.spec import flown_by, load_campaign

        spec = ESTIMATED_CAMPAIGN if kind == "campaign-ekf" else "paper_box"
        warm_up(flown_by(load_campaign(spec, runs=1), name))
    else:
        raise ValueError(f"unknown target {target!r}")
    return target, time.perf_counter() - start


def entries_of(target: str) -> list[tuple]:
    """The kernel entries a target compiles, as :func:`quadcommon.kernel.compiled` arguments."""
    kind, _, name = target.partition(":")
    if kind == "plant":
        from quadcommon.wire_values import FRAME_ENTRIES
        from simulator.dynamics.nominal_plant import nominal_kernels
        from simulator.dynamics.plant import plant_kernels
        from simulator.mavlink.hil import delivery_records

        kernels = (*plant_kernels(), *nominal_kernels(), *FRAME_ENTRIES, delivery_records)
        return [(fn,) for fn in kernels]
    if kind == "estimator":
        from autopilot.estimation.eskf import filter_kernels

        return [(fn,) for fn in filter_kernels()]
    if kind == "sensors":
        from simulator.sensors.models import sensor_kernels

        return [(fn,) for fn in sensor_kernels()]
    from autopilot.control import registry
    from autopilot.control.cascade import buffered_step
    from autopilot.control.config import load_controller

    config = load_controller(name)
    laws = (registry.law(registry.TRANSLATIONAL, config.translational.law).step,
            registry.law(registry.ROTATIONAL, config.rotational.law).step)  # fmt: skip
    if kind == "cascade":
        return [(buffered_step, *laws)]
    from sitl.campaign.kernels import ON_ESTIMATE, ON_TRUTH, simulate

    on = ON_ESTIMATE if kind == "campaign-ekf" else ON_TRUTH
    return [(simulate, *laws, *on, True)]  # nogil


def missing(names: Sequence[str]) -> list[str]:
    """The targets with an entry numba would have to compile (not in its cache yet)."""
    from quadcommon.kernel import cached

    out = []
    for target in names:
        for entry in entries_of(target):
            nogil = entry[-1] is True
            if not cached(*(entry[:-1] if nogil else entry), nogil=nogil):
                out.append(target)
                break
    return out


def compile_all(names: Sequence[str], workers: int | None = None, log=print) -> float:
    """Compile ``names`` (:func:`targets`) with ``workers`` processes; returns the wall time."""
    from quadcommon.kernel import compiling

    start = time.perf_counter()
    if not compiling():
        log("quadsitl compile: nothing to compile (numba missing or QUADSITL_PURE_PYTHON=1)")
        return 0.0
    workers = workers or os.cpu_count() or 1
    with ProcessPoolExecutor(max_workers=workers) as pool:
        for target, seconds in pool.map(compile_target, names):
            log(f"  {target}: {seconds:.1f} s")
    return time.perf_counter() - start


def main(argv: Sequence[str] | None = None) -> int:
    """``quadsitl compile``: compile the numba kernels of the given controllers' cascades (and the
    campaign engine's flights, unless ``--no-campaign``) into the cache, in parallel; 0."""
    from autopilot.control.config import CONTROLLER_NAMES

    parser = argparse.ArgumentParser(prog="quadsitl compile", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
    parser.add_argument("--controllers", nargs="+", default=list(CONTROLLER_NAMES), metavar="NAME",
                        help="the controllers whose cascade and campaign flight to compile (default: "
                        "the shipped ones; yours by name from your configuration directory)")  # fmt: skip
    parser.add_argument("--no-campaign", action="store_true", help="not the campaign engine's flights")
    parser.add_argument("--estimate", action="store_true",
                        help="also the campaign engine's flights on the EKF (campaigns with [estimation], "
                        "e.g. paper_box_gps)")  # fmt: skip
    parser.add_argument("--workers", type=int, default=None, help="processes (default: one per core)")
    parser.add_argument("--missing", action="store_true",
                        help="only the targets with an entry not in numba's cache yet (checked without "
                        "loading any: nothing to do costs a fraction of a second, not a process per core)")
    args = parser.parse_args(argv)
    names = targets(args.controllers, campaign=not args.no_campaign, estimate=args.estimate)
    if args.missing:
        names = missing(names)
        if not names:
            print("quadsitl compile: every target is in the cache")
            return 0
    print(f"quadsitl compile: {len(names)} targets")
    wall = compile_all(names, args.workers)
    print(f"quadsitl compile: done in {wall:.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
