"""Suite-wide wiring: the ``processes``, ``compat`` and ``second_namespace`` markers.

The tests that start processes or bind the SITL's fixed ports (:data:`PROCESS_MODULES`) get the
marker ``processes``; of those, the ones in :data:`COMPAT_MODULES` also ``compat``, and of those,
the ones in :data:`SECOND_NAMESPACE` also ``second_namespace``. ``make test`` runs the suite as
pytest sessions side by side on these markers (:mod:`tests.suite`): the in-process tests (in
simulation time: the large majority), the process tests one after another (their instances were
chosen not to collide with each other one at a time, and a lockstep pair of processes wants a core
of its own), and the compat tests in two network namespaces. A plain ``pytest`` runs everything
in order."""

from __future__ import annotations

import pytest

PROCESS_MODULES = {
    "tests/compat/",  # MAVSDK, MAVProxy, several vehicles, signing with real clients
    "tests/compat/test_mavsdk3.py",  # MAVSDK-Python 3 + quadsitl up in a network namespace
    "tests/view/test_browser_sitl.py",
    "tests/view/test_live_sitl.py",
    "tests/view/test_server.py",
    "tests/gcs_scripts/test_e2e_sitl.py",
    "tests/gcs_scripts/test_record_process.py",
    "tests/gcs_scripts/test_upload_gusts.py",
    "tests/gcs_scripts/test_upload_gusts_zenoh.py",
    "tests/gcs_scripts/test_upload_mission.py",
    "tests/simulator/test_sim_cli.py",
    "tests/simulator/test_sim_process.py",
    "tests/sitl/test_flight_log_process.py",
    "tests/sitl/test_hostile_udp.py",
    "tests/sitl/test_installed_wheel.py",
    "tests/sitl/test_launcher_ports.py",
    "tests/sitl/test_manual_modes_sitl.py",
    "tests/sitl/test_links_processes.py",
    "tests/sitl/test_paper_through_sitl.py",
    "tests/sitl/test_params_failsafes.py",
    "tests/sitl/test_signing_cli.py",
    "tests/sitl/test_sitl_vs_inprocess.py",
    "tests/sitl/test_own_law_sitl.py",
    "tests/sitl/test_up_cli.py",
    "tests/sitl/test_up_process_loss.py",
    "tests/sitl/test_estimator_accuracy_sitl.py",
    "tests/campaign/test_dask.py",
}


# Of those, the third session's (marker ``compat``, tests/suite.py): it runs in a network namespace
# of its own (``unshare -n``), so its ports never meet the other sessions' and its tests may use any
# instance. In it: the client-compatibility tests (MAVSDK, MAVProxy, several vehicles: they mostly
# wait on real clients paced to the wall clock; their port block is PX4's instances 100-119,
# tests/compat/vehicles.py) and, to balance the sessions' wall times (measured: the process session
# was the longest by ~150 s), signing with real clients (instances 70-72) and the view's tests on a
# live SITL (instances 65-69). Without namespaces they all run in the process session.
COMPAT_MODULES = {
    "tests/compat/", "tests/view/test_browser_sitl.py", "tests/view/test_live_sitl.py",
    "tests/sitl/test_installed_wheel.py", "tests/sitl/test_paper_through_sitl.py",
    "tests/sitl/test_manual_modes_sitl.py",  # the sticks paced on telemetry: a namespace of its own
}  # fmt: skip
NOT_COMPAT: set[str] = set()
# Of the compat tests, these (marker ``second_namespace``) run in a session of their own, in a
# namespace of its own too: MAVSDK's wait on real clients paced to the wall clock (~100 s of the
# ~220 s the compat session took alone, measured), so two namespaces side by side halve that wait
# for a little more CPU; the installed wheel (~30 s) and the paper through the SITL (~25 s) moved
# here and to the compat session from the process session, which was then the suite's last.
SECOND_NAMESPACE = {
    "tests/compat/test_mavsdk.py", "tests/compat/test_mavsdk3.py", "tests/sitl/test_installed_wheel.py",
}  # fmt: skip


def _listed(nodeid: str, entries: set[str]) -> bool:
    path = nodeid.split("::", 1)[0]
    return any(path == entry or (entry.endswith("/") and path.startswith(entry)) for entry in entries)


def _uses_processes(nodeid: str) -> bool:
    return _listed(nodeid, PROCESS_MODULES)


@pytest.hookimpl(tryfirst=True)  # before -m selects on the marker
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    for item in items:
        if _uses_processes(item.nodeid):
            item.add_marker(pytest.mark.processes)
            if _listed(item.nodeid, COMPAT_MODULES) and not _listed(item.nodeid, NOT_COMPAT):
                item.add_marker(pytest.mark.compat)
                if _listed(item.nodeid, SECOND_NAMESPACE):
                    item.add_marker(pytest.mark.second_namespace)

