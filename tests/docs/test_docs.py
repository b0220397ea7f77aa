"""The documentation's own checks, in-process and fast: every relative link and anchor in docs/,
README.md, CONTRIBUTING.md and CHANGELOG.md leads somewhere, every page is in mkdocs.yml's
navigation (and every navigation entry is a page), and the environment-variable table is
quadcommon.environment's. ``make docs`` (``mkdocs build --strict``) checks the rendered site too.
"""

from __future__ import annotations

import re
import unicodedata
from pathlib import Path

import pytest

from autopilot.mavlink import telemetry, validation
from autopilot.mission import items, plans
from quadcommon import environment

REPO = Path(__file__).resolve().parents[2]
DOCS = REPO / "docs"
ROOT_PAGES = [REPO / name for name in ("README.md", "CONTRIBUTING.md", "CHANGELOG.md")]

FENCE = re.compile(r"^(```|~~~).*?^\1", re.M | re.S)
CODE_SPAN = re.compile(r"(`+)[^`].*?\1", re.S)
LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\]]*\])*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
HEADING = re.compile(r"^(#{1,6})\s+(.*?)\s*#*\s*$", re.M)
NAV_PAGE = re.compile(r"^\s*-\s*(?:[^:\n]+:\s*)?([\w./-]+\.md)\s*$", re.M)


def prose(text: str) -> str:
    """The Markdown without its code blocks and code spans (links there are not links)."""
    return CODE_SPAN.sub("", FENCE.sub("", text))


def slug(heading: str) -> str:
    """The anchor Python-Markdown's toc extension (MkDocs) gives a heading."""
    parts = re.split(r"(`[^`]*`)", heading)  # emphasis and links only outside code spans
    for i in range(0, len(parts), 2):
        part = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", parts[i])  # a link's text
        part = re.sub(r"\*{1,2}([^*]+)\*{1,2}", r"\1", part)
        parts[i] = re.sub(r"(?<!\w)_{1,2}([^_]+)_{1,2}(?!\w)", r"\1", part)
    text = "".join(p.strip("`") if p.startswith("`") else p for p in parts)
    text = re.sub(r"<[^>]+>", "", text)
    text = unicodedata.normalize("NFKD", text).encode("ascii", "ignore").decode("ascii")
    text = re.sub(r"[^\w\s-]", "", text).strip().lower()
    return re.sub(r"[-\s]+", "-", text)


def anchors(page: Path) -> set[str]:
    seen: dict[str, int] = {}
    result = set()
    for _, title in HEADING.findall(FENCE.sub("", page.read_text())):
        base = slug(title)
        n = seen.get(base, 0)
        seen[base] = n + 1
        result.add(base if n == 0 else f"{base}_{n}")
    return result


def pages() -> list[Path]:
    return sorted(DOCS.rglob("*.md")) + [p for p in ROOT_PAGES if p.exists()]


def broken_links(page: Path) -> list[str]:
    """The page's relative links whose file or anchor does not exist."""
    problems = []
    for target in LINK.findall(prose(page.read_text())):
        if re.match(r"^[a-z][a-z0-9+.-]*:", target):  # https:, mailto:, ...
            continue
        path_text, _, anchor = target.partition("#")
        destination = (page.parent / path_text).resolve() if path_text else page
        where = f"{page.relative_to(REPO)}: ({target})"
        if not destination.exists():
            problems.append(f"{where} leads nowhere")
            continue
        if page.is_relative_to(DOCS) and not destination.is_relative_to(DOCS):
            problems.append(f"{where} leaves docs/ (the site has only docs/; name the file in `code`)")
            continue
        if anchor and destination.suffix == ".md" and anchor not in anchors(destination):
            problems.append(f"{where}: no heading #{anchor} in {destination.relative_to(REPO)}")
    return problems


@pytest.mark.parametrize("page", pages(), ids=lambda p: str(p.relative_to(REPO)))
def test_relative_links_lead_somewhere(page: Path) -> None:
    assert broken_links(page) == []


def test_the_link_check_finds_broken_links(tmp_path: Path) -> None:
    page = DOCS / "__probe_for_the_test.md"
    page.write_text(
        "# Probe\n\n[gone](missing.md) [anchor](running.md#no-such-heading) [out](../README.md)\n"
        "[fine](running.md#ports-and-instances) `[code](nowhere.md)`\n\n```\n[block](nowhere.md)\n```\n"
    )
    try:
        problems = broken_links(page)
    finally:
        page.unlink()
    assert len(problems) == 3, problems
    assert "missing.md" in problems[0] and "no-such-heading" in problems[1] and "leaves docs/" in problems[2]


def test_slugs_are_mkdocs_anchors() -> None:
    assert slug("Specs (`config/campaigns/*.toml`)") == "specs-configcampaignstoml"
    assert slug("Starting a vehicle: `quadsitl up`") == "starting-a-vehicle-quadsitl-up"
    assert slug("The paper's ±30 % box") == "the-papers-30-box"
    heading = "Stick override (`COM_RC_OVERRIDE`, `COM_RC_STICK_OV`)"
    assert slug(heading) == "stick-override-com_rc_override-com_rc_stick_ov"
    assert slug("**Bold** and _it_ [link](x.md)") == "bold-and-it-link"


def test_every_page_is_in_the_navigation() -> None:
    nav = set(NAV_PAGE.findall((REPO / "mkdocs.yml").read_text()))
    on_disk = {str(p.relative_to(DOCS)) for p in DOCS.rglob("*.md")}
    assert on_disk - nav == set(), "pages missing from mkdocs.yml's nav"
    assert nav - on_disk == set(), "nav entries without a page"


def test_environment_table_is_the_modules() -> None:
    """docs/configuration.md shows quadcommon.environment.VARIABLES as they are."""
    assert environment.markdown_table() in (DOCS / "configuration.md").read_text()


def test_parameter_slot_tables_are_the_modules() -> None:
    """docs/security.md and docs/missions.md show the slots of the handled commands and items, and
    the overrides, as autopilot.mavlink.validation derives them (print the tables with
    ``validation.slots_table(...)`` / ``validation.overrides_table()`` to update the pages)."""
    security, missions = (DOCS / "security.md").read_text(), (DOCS / "missions.md").read_text()
    assert validation.slots_table(validation.COMMAND_RULES) in security
    assert validation.overrides_table() in security
    item_commands = items.SUPPORTED_COMMANDS | plans.FENCE_COMMANDS | plans.RALLY_COMMANDS
    assert validation.slots_table(item_commands) in missions


def test_the_streams_table_is_the_modules() -> None:
    """docs/compatibility.md shows autopilot.mavlink.telemetry.STREAMS as it is (print
    ``telemetry.streams_table()`` to update the page)."""
    assert telemetry.streams_table() in (DOCS / "compatibility.md").read_text()


# Development history in user-facing text: issue numbers, review findings, dates of measurements,
# "before:" diaries, line counts of files. The history lives in CHANGELOG.md and git; the benchmarks
# page keeps the dates of its figures. A date between slashes is a path (PX4's log/YYYY-MM-DD/).
HISTORY = re.compile(
    r"\b[Ii]ssues? #?\d+|\b[Ff]inding \d+|(?<!/)\b20\d\d-\d\d-\d\d\b(?!/)|\bBefore:\s|~[\d,]+ lines\b"
)
HISTORY_ALLOWED = {
    "docs/benchmarks.md": re.compile(r"20\d\d-\d\d-\d\d"),  # its dated table
    "autopilot/mavlink/signing.py": re.compile(r"2015-01-01"),  # MAVLink signing's epoch
    "docs/security.md": re.compile(r"2015-01-01|issue 1060"),  # the epoch; MAVSDK's tracker, linked
    "tests/gcs_scripts/test_upload_gusts.py": re.compile(r"2024-01-01"),  # a TOML date as bad input
    "tests/autopilot/logger/test_logger.py": re.compile(r"2025-06-15"),  # a log directory's expected name
}
SOURCE_DIRS = ("autopilot", "simulator", "quadcommon", "gcs_scripts", "sitl", "benchmarks", "config", "tests")


def user_facing_files() -> list[Path]:
    files = [REPO / "README.md", REPO / "CONTRIBUTING.md", *sorted(DOCS.rglob("*.md"))]
    for folder in SOURCE_DIRS:
        for pattern in ("*.py", "*.toml", "*.md", "*.js", "*.html"):
            files += [p for p in sorted((REPO / folder).rglob(pattern))
                      if "node_modules" not in p.parts and "vendor" not in p.parts]  # fmt: skip
    return [p for p in files if p.exists() and p != Path(__file__)]


def history_in(path: Path) -> list[str]:
    relative = str(path.relative_to(REPO))
    allowed = HISTORY_ALLOWED.get(relative)
    hits = []
    for number, line in enumerate(path.read_text(errors="replace").splitlines(), 1):
        for match in HISTORY.finditer(line):
            if allowed is not None and allowed.fullmatch(match.group(0)):
                continue
            hits.append(f"{relative}:{number}: {match.group(0)!r} in {line.strip()[:100]!r}")
    return hits


def test_no_development_history_in_user_facing_text() -> None:
    """README, docs, --help, docstrings and comments describe the product as it is."""
    hits = [hit for path in user_facing_files() for hit in history_in(path)]
    assert hits == []


# Narration in the pages a user reads: a diary of how the product got here instead of what it is
# ("at the time of writing", "the earlier run found ...", "it is 5 s now", "no longer", ...).
# Phrases, not words: "now" and "earlier" alone describe the product too ("what each channel does
# now", "saturates earlier").
DIARY = re.compile(
    r"\bat the time of writing\b"
    r"|\b(?:the|an|our|this) earlier (?:run|version|release|session|measurement|attempt|code|fix)s?\b"
    r"|\b(?:it|this|that|which) (?:is|was) [\d.,]+ ?[a-zµ%]* now\b"
    r"|\b(?:is|are) now\b|\bnow (?:does|uses|has|takes|flies|refuses|accepts|waits|works)\b"
    r"|\bused to (?:be|have|take|give|fly|say|refuse|accept|wait|fail|work)\b"
    r"|\bno longer\b|\bany ?more\b|\bpreviously\b|\bformerly\b|\brecently\b"
    r"|\bas of (?:now|today|this|the (?:latest|current)|version|release|commit|v?\d"
    r"|(?:jan|feb|mar|apr|may|jun|jul|aug|sep|oct|nov|dec)[a-z]*)\b"
    r"|\b(?:this|last|the previous|the last) (?:session|sitting|wave)\b"
    r"|\b(?:was|were|has been|have been) (?:fixed|changed|renamed|removed|added|rewritten|reworked|moved"
    r"|introduced|dropped)\b",
    re.IGNORECASE,
)


def narrated_pages() -> list[Path]:
    return [REPO / "README.md", REPO / "CONTRIBUTING.md", *sorted(DOCS.rglob("*.md"))]


def diary_in(path: Path) -> list[str]:
    relative = str(path.relative_to(REPO))
    return [
        f"{relative}:{number}: {match.group(0)!r} in {line.strip()[:100]!r}"
        for number, line in enumerate(path.read_text().splitlines(), 1)
        for match in DIARY.finditer(line)
    ]


def test_no_narration_in_the_pages() -> None:
    """README, CONTRIBUTING and docs/ say what the product is and does, not how it got there
    (that is CHANGELOG.md's and git's)."""
    hits = [hit for path in narrated_pages() for hit in diary_in(path)]
    assert hits == []


def test_the_narration_check_finds_narration() -> None:
    planted = [
        "Measured at the time of writing.", "The earlier run found 8 frames.", "It is 5 s now.",
        "The recorder is now faster.", "It used to be 1 s.", "A stream no longer holds it back.",
        "Previously the join waited.", "As of version 0.2 it waits.", "In this session we fixed it.",
        "The timeout was changed to 5 s.", "It now takes 5 s.",
    ]
    fine = [
        "The key used to sign the stream.", "What each channel does now:", "It saturates earlier.",
        "The session's Parquet.", "A recorder session ends at the disarm.", "It is 5 s long.",
    ]
    probe = DOCS / "__probe_narration.md"
    probe.write_text("\n".join(planted + fine) + "\n")
    try:
        hits = diary_in(probe)
    finally:
        probe.unlink()
    assert len(hits) == len(planted), hits
    assert all(f":{i}:" in hit for i, hit in enumerate(hits, 1)), hits


def test_the_history_check_finds_history(tmp_path: Path) -> None:
    probe = tmp_path / "probe.md"
    probe.write_text("Fixed in issue 9.\nMeasured 2026-12-02.\nBefore: 3 s.\n(~800 lines)\nfine text\n")
    probe_in_repo = DOCS / "__probe_history.md"
    probe_in_repo.write_text(probe.read_text())
    try:
        assert len(history_in(probe_in_repo)) == 4
    finally:
        probe_in_repo.unlink()


def test_failure_table_is_the_modules():
    """docs/failures.md shows quadcommon.failures.FAILURES as it is."""
    from quadcommon import failures

    assert failures.markdown_table() in (DOCS / "failures.md").read_text()
