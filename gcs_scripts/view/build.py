"""Fetch the view's JavaScript libraries from the npm registry (pinned) into ``static/vendor/``.

``python -m gcs_scripts.view.build`` (``make`` runs it for ``make test`` and ``make demo``):

1. if ``static/vendor/MANIFEST.json`` matches ``package-lock.json`` and every file it lists is
   there with its SHA-256, nothing is done: no network, so a machine that fetched once works
   offline from then on;
2. otherwise ``npm ci`` installs exactly the versions of ``package-lock.json`` (exact versions in
   ``package.json``, sha512 integrity of each tarball in the lock; ``--ignore-scripts``: no
   install scripts run; ``--prefer-offline``: npm's cache first) into ``node_modules/`` beside this
   file, and the few dist files the page loads are copied into ``static/vendor/`` with their
   licences, and the manifest is written.

The page loads only these files, from the view's own server: never a CDN (the machines are
offline). The vendored files are not committed; they are build output (``.gitignore``).
``--check`` only verifies (exit 1 if the vendor folder is missing or stale).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import shutil
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
PACKAGE_JSON = HERE / "package.json"
PACKAGE_LOCK = HERE / "package-lock.json"
NODE_MODULES = HERE / "node_modules"
VENDOR = HERE / "static" / "vendor"
MANIFEST = VENDOR / "MANIFEST.json"

# node_modules path -> path under static/vendor/
FILES: dict[str, str] = {
    "three/build/three.module.js": "three/three.module.js",
    "three/build/three.core.js": "three/three.core.js",
    "three/examples/jsm/controls/OrbitControls.js": "three/addons/controls/OrbitControls.js",
    "three/examples/jsm/renderers/CSS2DRenderer.js": "three/addons/renderers/CSS2DRenderer.js",
    "three/LICENSE": "three/LICENSE",
    "uplot/dist/uPlot.iife.min.js": "uplot/uPlot.iife.min.js",
    "uplot/dist/uPlot.min.css": "uplot/uPlot.min.css",
    "uplot/LICENSE": "uplot/LICENSE",
}


class BuildError(RuntimeError):
    pass


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def locked_versions() -> dict[str, str]:
    """Package -> version, as pinned by ``package-lock.json``."""
    lock = json.loads(PACKAGE_LOCK.read_text())
    pins = json.loads(PACKAGE_JSON.read_text())["dependencies"]
    out = {}
    for name, wanted in pins.items():
        entry = lock.get("packages", {}).get(f"node_modules/{name}")
        if entry is None:
            raise BuildError(f"{PACKAGE_LOCK}: no entry for {name} (run npm install --package-lock-only)")
        if entry["version"] != wanted:
            raise BuildError(f"{PACKAGE_LOCK}: {name} {entry['version']} but package.json pins {wanted}")
        out[name] = entry["version"]
    return out


def vendor_problem() -> str | None:
    """Why ``static/vendor/`` cannot be used as it is (None: it is complete and current)."""
    if not MANIFEST.exists():
        return f"{MANIFEST} is missing"
    try:
        manifest = json.loads(MANIFEST.read_text())
        versions = locked_versions()
    except (ValueError, KeyError, BuildError) as exc:
        return f"cannot compare {MANIFEST} with the lock: {exc}"
    if manifest.get("versions") != versions:
        return f"vendored {manifest.get('versions')} but package-lock.json pins {versions}"
    for target in FILES.values():
        path = VENDOR / target
        if not path.exists():
            return f"{path} is missing"
        if manifest.get("files", {}).get(target) != _sha256(path):
            return f"{path} differs from the manifest"
    return None


def build(quiet: bool = False) -> bool:
    """Make ``static/vendor/`` current; True if anything was fetched or copied."""
    problem = vendor_problem()
    if problem is None:
        MANIFEST.touch()  # newer than the lock again: make's rule is satisfied without running
        if not quiet:
            print(f"view build: {VENDOR} is up to date ({locked_versions()})")
        return False
    if not quiet:
        print(f"view build: {problem}; installing the pinned packages with npm ci in {HERE}")
    npm = shutil.which("npm")
    if npm is None:
        raise BuildError(
            "npm is not installed: the view's JavaScript libraries (three, uplot) come from the npm "
            "registry at build time (install Node.js + npm, then run: python -m gcs_scripts.view.build)"
        )
    cmd = [npm, "ci", "--ignore-scripts", "--no-audit", "--no-fund", "--prefer-offline", "--loglevel=error"]
    result = subprocess.run(cmd, cwd=HERE, capture_output=True, text=True, timeout=600)
    if result.returncode != 0:
        raise BuildError(
            f"{' '.join(cmd)} failed in {HERE}:\n{result.stdout[-2000:]}\n{result.stderr[-2000:]}"
        )
    versions = locked_versions()
    for name, version in versions.items():
        installed = json.loads((NODE_MODULES / name / "package.json").read_text())["version"]
        if installed != version:
            raise BuildError(f"npm installed {name} {installed}, the lock pins {version}")
    if VENDOR.exists():
        shutil.rmtree(VENDOR)
    digests = {}
    for source, target in FILES.items():
        src, dst = NODE_MODULES / source, VENDOR / target
        if not src.exists():
            raise BuildError(f"{src} is not in the installed package (layout changed?)")
        dst.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(src, dst)
        digests[target] = _sha256(dst)
    manifest = {"versions": versions, "files": digests, "from": "npm registry via npm ci (package-lock.json)"}
    MANIFEST.write_text(json.dumps(manifest, indent=2) + "\n")
    if not quiet:
        print(f"view build: copied {len(FILES)} files of {versions} into {VENDOR}")
    return True


def main(argv: list[str] | None = None) -> int:
    """Build the view's vendored JavaScript into static/vendor/ (``--check``: only verify, 1 if stale)."""
    parser = argparse.ArgumentParser(
        prog="python -m gcs_scripts.view.build",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--check", action="store_true", help="only verify static/vendor/ (exit 1 if stale)")
    args = parser.parse_args(argv)
    if args.check:
        problem = vendor_problem()
        print(f"view build: {problem or 'static/vendor/ is up to date'}")
        return 1 if problem else 0
    try:
        build()
    except (BuildError, subprocess.TimeoutExpired) as exc:
        print(f"view build: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
