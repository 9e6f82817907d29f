"""Where a result came from: the code that produced it (package version, git commit, uncommitted changes) and a
short stable hash of the settings that change it, for naming result folders."""

import hashlib
import json
import subprocess
from importlib import metadata
from pathlib import Path

SOURCE_ROOT = Path(__file__).resolve().parents[2]  # the folder holding the package: a checkout, or site-packages


def _git(*args: str) -> str | None:
    try:
        done = subprocess.run(["git", "-C", str(SOURCE_ROOT), *args], capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return None  # no git, or it hung
    return done.stdout.strip() if done.returncode == 0 else None


# What decides a run: the code, the configs and the frozen models it loads. Results elsewhere in the checkout are
# not code: an experiment that records into its committed journal (benchmarks/results/...) changes a tracked file
# with every run, and called its own clean checkout dirty.
CODE_PATHS = ("roshan", "configs", "models", "pyproject.toml")


def code_version() -> dict:
    """``{"version", "commit", "dirty"}``: the installed package version, and the git commit of the checkout the
    code runs from with whether tracked files of :data:`CODE_PATHS` differ from it (both ``None`` outside a git
    checkout, e.g. a wheel installed into site-packages)."""
    try:
        version = metadata.version("roshan")
    except metadata.PackageNotFoundError:
        version = None
    commit = dirty = None
    top = _git("rev-parse", "--show-toplevel")
    # only the package's own checkout: site-packages inside some other repository must not borrow its commit
    if top is not None and Path(top).resolve() == SOURCE_ROOT:
        commit = _git("rev-parse", "HEAD")
        status = _git("status", "--porcelain", "--untracked-files=no", "--", *CODE_PATHS)
        dirty = None if status is None else bool(status)
    return {"version": version, "commit": commit, "dirty": dirty}


def settings_hash(settings: dict) -> str:
    """8 hex digits of a JSON-able dict, independent of key order (the same settings always give the same hash)."""
    return hashlib.sha256(json.dumps(settings, sort_keys=True).encode()).hexdigest()[:8]
