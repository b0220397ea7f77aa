"""The view server without a vehicle: static files, the WebSocket hello of a replay, the CLI."""

from __future__ import annotations

import json
import re
import socket
import urllib.error
import urllib.request

import pytest

from gcs_scripts.view import build
from gcs_scripts.view.server import ReplaySource, main

from .helpers import served
from .test_replay import _session

pytestmark = [pytest.mark.processes, pytest.mark.timeout(60)]


def _get(url: str) -> tuple[int, str, bytes]:
    try:
        with urllib.request.urlopen(url, timeout=5) as r:
            return r.status, r.headers["Content-Type"], r.read()
    except urllib.error.HTTPError as exc:
        return exc.code, exc.headers["Content-Type"], exc.read()


def test_vendor_files_are_built_and_match_the_lock():
    assert build.vendor_problem() is None, "run python -m gcs_scripts.view.build (make test does)"
    manifest = json.loads(build.MANIFEST.read_text())
    pins = json.loads(build.PACKAGE_JSON.read_text())["dependencies"]
    assert manifest["versions"] == pins
    assert all(re.fullmatch(r"\d+\.\d+\.\d+", v) for v in pins.values()), "exact versions only"


def test_page_loads_nothing_from_outside():
    """No address but the view's own: the machines are offline, and a CDN is not wanted anyway."""
    for path in build.HERE.joinpath("static").glob("*.*"):
        text = path.read_text()
        assert not re.search(r"https?://|(src|href)\s*=\s*[\"']//", text), path
        assert "ws://${location.host}" in text or path.suffix != ".js", path


def test_static_files_and_replay_hello(tmp_path):
    from websockets.sync.client import connect

    source = ReplaySource([str(_session(tmp_path))], labels=["my run"])
    with served(source) as server:
        base = server.url
        status, kind, body = _get(base)
        assert status == 200 and kind.startswith("text/html") and b"quadsitl view" in body
        status, kind, _ = _get(base + "view.js")
        assert status == 200 and kind == "text/javascript"  # ES modules need a JavaScript type
        status, kind, _ = _get(base + "vendor/three/three.core.js")
        assert status == 200 and kind == "text/javascript"
        assert _get(base + "vendor/uplot/uPlot.min.css")[1] == "text/css"
        assert _get(base + "nothing.js")[0] == 404
        assert _get(base + "..%2f..%2fpyproject.toml")[0] == 404
        assert _get(base + "../../../pyproject.toml")[0] == 404
        with connect(base.replace("http", "ws") + "ws", open_timeout=5) as ws:
            hello = json.loads(ws.recv(timeout=5))
        assert hello["type"] == "hello" and hello["kind"] == "replay"
        (track,) = hello["tracks"]
        assert track["label"] == "my run" and track["color"].startswith("#")
        assert len(track["cols"]["t"]) == len(track["cols"]["x"]) > 10


def test_cli_refuses_bad_arguments(tmp_path, capsys):
    with pytest.raises(SystemExit):
        main(["--count", "2", "--instance", "1", "2"])
    with pytest.raises(SystemExit):
        main([str(tmp_path / "x.parquet"), "--instance", "3"])
    with pytest.raises(SystemExit):
        main(["--instance", "250"])
    assert main(["--rate", "60", "--instance", "60", "--port", "0"]) == 2
    assert "--rate must be in (0, 30]" in capsys.readouterr().err
    assert main([str(tmp_path / "missing.parquet")]) == 2
    assert "no session log" in capsys.readouterr().err


def test_cli_port_in_use_is_an_error_naming_it(tmp_path, capsys):
    log = _session(tmp_path)
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        assert main([str(log), "--port", str(port), "--no-nice"]) == 2
    assert f"TCP port {port} (127.0.0.1) is already in use" in capsys.readouterr().err


def test_replay_page_shows_the_recorded_failsafe_and_modes_at_the_slider_time(tmp_path):
    """The page's own reading of a recorded session (the JavaScript mirror of the failsafe rules)."""
    from .helpers import browser_page

    source = ReplaySource([str(_session(tmp_path))])
    with served(source) as server, browser_page(server.url) as page:
        page.wait_for_function("() => window.quadsitlView.kind === 'replay'", timeout=20000)

        def at(t: float) -> tuple[str, str, str]:
            page.fill("#slider", str(t))
            page.dispatch_event("#slider", "input")
            page.wait_for_function(
                f"() => Math.abs(window.quadsitlView.replay.t - {t}) < 0.01 && !window.quadsitlView.dirtyUi",
                timeout=5000,
            )
            page.wait_for_timeout(300)  # the cards follow at the page's text rate
            card = ".card[data-id='0']"
            return (
                page.inner_text(f"{card} .mode"),
                page.inner_text(f"{card} .arm"),
                page.inner_text(f"{card} .failsafe"),
            )

        assert at(0.8) == ("AUTO.LOITER", "disarmed", "none")
        assert at(3.9) == ("OFFBOARD", "ARMED", "offboard loss")
        texts = page.locator("#texts li").all_inner_texts()
        assert any("offboard setpoints lost" in t for t in texts)
        assert page.errors == []


def test_a_vehicle_is_placed_where_its_home_is_in_the_first_ones_frame():
    """The scene is the first vehicle's local frame; another vehicle's home 3 m north and 4 m east
    of it is drawn at x = 3 (north), y = -4 (west), z = 1 (up), its home 1 m higher."""
    from gcs_scripts.view.server import home_offset_m
    from quadcommon import frames

    origin = (47.397742, 8.545594, 488.0)
    there = frames.ned_to_geodetic(3.0, 4.0, -1.0, origin)
    x, y, z = home_offset_m(there, origin)
    assert (x, y, z) == pytest.approx((3.0, -4.0, 1.0), abs=1e-3)
    assert home_offset_m(origin, origin) == [0.0, 0.0, 0.0]
    assert home_offset_m(None, origin) is None and home_offset_m(there, None) is None
