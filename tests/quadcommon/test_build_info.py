"""The build's version and commit as PX4 encodes them, and the commit read from a checkout's .git
(a branch, packed refs, a detached HEAD, a worktree) without running git."""

from __future__ import annotations

import shutil
import subprocess

import pytest

from quadcommon import build_info
from quadcommon.build_info import BuildInfo, checkout_commit, flight_sw_version

A = "0123456789abcdef0123456789abcdef01234567"
B = "fedcba9876543210fedcba9876543210fedcba98"


@pytest.mark.parametrize(
    "version, encoded",
    [
        ("1.14.3", 0x010E03FF),  # a release: type 255 (FIRMWARE_VERSION_TYPE_OFFICIAL), as PX4's v1.14.3
        ("0.1.0", 0x000100FF),
        ("v1.2", 0x010200FF),
        ("2.0.0rc1", 0x020000C0),  # release candidate 192
        ("2.0.0b2", 0x02000080),  # beta 128
        ("2.0.0a1", 0x02000040),  # alpha 64
        ("0.2.0.dev3", 0x00020000),  # development 0
        ("0.1.0+g1234", 0x00010000),  # a local build: development
        ("300.1.1", 0xFF0101FF),  # each part at most 255
        ("", 0),
        ("unknown", 0),
    ],
)
def test_flight_sw_version_is_px4s_encoding(version, encoded):
    assert flight_sw_version(version) == encoded


def test_custom_version_is_the_commit_as_px4_sends_it():
    build = BuildInfo("1.0.0", A)
    assert build.custom_version == [0xEF, 0xCD, 0xAB, 0x89, 0x67, 0x45, 0x23, 0x01]
    assert "".join(f"{b:02x}" for b in reversed(build.custom_version)) == A[:16]  # how QGC prints it
    assert BuildInfo("1.0.0").custom_version == [0] * 8 and BuildInfo().commit_text == "unknown"


def repository(root, head: str):
    git = root / ".git"
    (git / "refs" / "heads").mkdir(parents=True)
    (git / "HEAD").write_text(head + "\n")
    return git


def test_the_commit_of_a_branch_of_packed_refs_and_of_a_detached_head(tmp_path):
    git = repository(tmp_path / "a", "ref: refs/heads/main")
    (git / "refs" / "heads" / "main").write_text(A + "\n")
    assert checkout_commit(git) == A
    git = repository(tmp_path / "b", "ref: refs/heads/topic/x")
    packed = f"# pack-refs with: peeled\n{B} refs/heads/main\n{A} refs/heads/topic/x\n"
    (git / "packed-refs").write_text(packed)
    assert checkout_commit(git) == A
    assert checkout_commit(repository(tmp_path / "c", B.upper())) == B  # detached


def test_the_commit_of_a_worktree_follows_its_gitdir_file(tmp_path):
    main = repository(tmp_path / "main", "ref: refs/heads/main")
    (main / "refs" / "heads" / "feature").write_text(B + "\n")
    linked = main / "worktrees" / "feature"
    linked.mkdir(parents=True)
    (linked / "HEAD").write_text("ref: refs/heads/feature\n")
    (linked / "commondir").write_text("../..\n")
    tree = tmp_path / "tree"
    tree.mkdir()
    (tree / ".git").write_text(f"gitdir: {linked}\n")
    assert checkout_commit(tree / ".git") == B


@pytest.mark.parametrize("head", ["ref: refs/heads/gone", "not a hash", "", "ref: refs/heads/main"])
def test_no_commit_where_there_is_none_to_read(tmp_path, head):
    git = repository(tmp_path, head)
    if head.endswith("main"):
        (git / "refs" / "heads" / "main").write_text("garbage\n")
    assert checkout_commit(git) is None
    assert checkout_commit(tmp_path / "nowhere" / ".git") is None


@pytest.mark.skipif(shutil.which("git") is None, reason="git is not installed")
def test_this_checkout_reads_as_git_says():
    """Run from a checkout, the build's commit is the one git reports (worktree or not)."""
    if not (build_info.CHECKOUT / ".git").exists():
        pytest.skip("not run from a checkout")
    head = subprocess.run(["git", "-C", str(build_info.CHECKOUT), "rev-parse", "HEAD"], capture_output=True,
                          text=True, timeout=30).stdout.strip()  # fmt: skip
    build = build_info.this_build()
    assert build.commit == head and build.version
