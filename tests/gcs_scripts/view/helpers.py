"""Shared pieces of the view tests: a view server in a thread, Chromium through Playwright."""

from __future__ import annotations

import asyncio
import shutil
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from gcs_scripts.view.server import LiveSource, ReplaySource, ViewServer

REPO = Path(__file__).resolve().parents[3]
ARTIFACTS = REPO / "out" / "test-artifacts" / "view"
CHROMIUM = "/usr/bin/chromium"
# What works on these machines (no GPU, closed network): see the machine notes.
CHROMIUM_ARGS = [
    "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
    "--disable-component-update", "--disable-sync",
]  # fmt: skip


@contextmanager
def served(source: LiveSource | ReplaySource, rate_hz: float = 30.0) -> Iterator[ViewServer]:
    """A ViewServer on an ephemeral loopback port, in its own thread and event loop."""
    server = ViewServer(source, port=0, rate_hz=rate_hz)
    ready = threading.Event()
    loop = asyncio.new_event_loop()
    stop: list[asyncio.Event] = []
    failure: list[BaseException] = []

    async def main() -> None:
        stop.append(asyncio.Event())
        await server.run(stop[0], lambda url: ready.set())

    def run() -> None:
        try:
            loop.run_until_complete(main())
        except BaseException as exc:  # reported to the test below
            failure.append(exc)
            ready.set()

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    assert ready.wait(20.0), "the view server did not start within 20 s"
    if failure:
        raise failure[0]
    try:
        yield server
    finally:
        loop.call_soon_threadsafe(stop[0].set)
        thread.join(10.0)
        loop.close()


def require_chromium() -> None:
    if shutil.which("chromium") is None:
        pytest.fail(
            "Debian's chromium is not installed: `make test` installs it (apt-get install -y chromium)"
        )


@contextmanager
def browser_page(url: str, width: int = 1280, height: int = 900) -> Iterator:
    """A headless Chromium page (the Debian browser, never a downloaded one) at ``url``."""
    from playwright.sync_api import sync_playwright

    require_chromium()
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
        try:
            page = browser.new_page(viewport={"width": width, "height": height})
            errors: list[str] = []
            page.on("pageerror", lambda exc: errors.append(str(exc)))
            page.goto(url)
            page.errors = errors  # type: ignore[attr-defined]
            yield page
        finally:
            browser.close()


def view_state(page) -> dict:
    return page.evaluate(
        """() => { const s = window.quadsitlView; return {
            kind: s.kind, connected: s.connected, messages: s.messages, frames: s.frames, rateHz: s.rateHz,
            renders3d: s.renders3d, plotDraws: s.plotDraws, errors: s.errors, modeHistory: s.modeHistory,
            samples: s.tracks.map(t => t.cols.t.length), replay: {t: s.replay.t, t0: s.replay.t0,
            t1: s.replay.t1, playing: s.replay.playing, ended: s.replay.ended} }; }"""
    )
