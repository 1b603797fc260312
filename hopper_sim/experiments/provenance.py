"""Provenance of written results: which scenario, checkpoint and code produced them.

Every result hopnav writes (a run's JSON, the sweep CSVs and ``sweep_meta.json``, a rerun
recording, a figure's PNG metadata, a Q-table) carries the fields of :func:`provenance`:

``scenario``
    the scenario's name.
``scenario_sha256``
    :func:`scenario_digest`: SHA-256 of the scenario's definition (world, regions, start,
    formula, labels, rewards, P_sat, runner settings, description) in a canonical JSON form,
    so it changes when the scenario changes and not when a comment or the key order of its
    TOML file does. The command line takes it before its own overrides (``--max-steps``,
    ``--runs``, ``--seed``), which are arguments of the invocation, not of the scenario.
``checkpoint_sha256``
    SHA-256 of the controller checkpoint file used (``None`` where no controller ran).
``hopnav_version``
    the package version.
``git_commit``, ``git_dirty``
    the commit of the source tree the code was imported from and whether tracked files
    differ from it, when that tree is a git work tree in which the package is tracked
    (``None`` for an installed wheel).

``--resume`` (sweep) and ``--q-table`` (run) compare ``scenario_sha256`` with
:func:`require_same_scenario` and refuse results of another scenario.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import os
import subprocess
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from hopper_sim.errors import HopperSimError

if TYPE_CHECKING:
    from planner.scenario import Scenario

#: The keys :func:`provenance` returns, in order.
FIELDS: tuple[str, ...] = (
    "scenario",
    "scenario_sha256",
    "checkpoint_sha256",
    "hopnav_version",
    "git_commit",
    "git_dirty",
)


class ProvenanceError(HopperSimError, ValueError):
    """A result belongs to another scenario (or carries no provenance to tell)."""


def _canonical(value: Any) -> Any:
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: _canonical(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, Mapping):
        return {str(k): _canonical(v) for k, v in sorted(value.items())}
    if isinstance(value, list | tuple):
        return [_canonical(v) for v in value]
    if isinstance(value, bool | int | str) or value is None:
        return value
    if isinstance(value, float):
        return float(value)
    raise TypeError(f"cannot digest a {type(value).__name__} in a scenario")


def scenario_digest(scenario: Scenario) -> str:
    """SHA-256 (hex) of ``scenario``'s definition in canonical JSON (see the module doc)."""
    text = json.dumps(_canonical(scenario), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


@functools.lru_cache(maxsize=16)
def _file_sha256(path: str, size: int, mtime_ns: int) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def file_sha256(path: str | os.PathLike[str]) -> str:
    """SHA-256 (hex) of a file's bytes (cached per path, size and modification time)."""
    st = os.stat(path)
    return _file_sha256(os.fspath(path), st.st_size, st.st_mtime_ns)


def package_version() -> str:
    """hopnav's version (:data:`hopnav.__version__`)."""
    from hopnav import __version__

    return __version__


@functools.lru_cache(maxsize=1)
def git_state() -> tuple[str | None, bool | None]:
    """``(commit, dirty)`` of the git work tree the code was imported from, or
    ``(None, None)`` when the package is not tracked in one (an installed wheel)."""
    here = Path(__file__).resolve().parent

    def git(*args: str) -> str | None:
        try:
            proc = subprocess.run(
                ["git", "-C", str(here), *args],
                capture_output=True,
                text=True,
                timeout=10,
                check=False,
            )
        except (OSError, subprocess.SubprocessError):
            return None
        return proc.stdout.strip() if proc.returncode == 0 else None

    # the package must be tracked there: a venv inside a checkout is not the checkout's code
    if git("ls-files", "--error-unmatch", "provenance.py") is None:
        return None, None
    commit = git("rev-parse", "HEAD")
    if commit is None:
        return None, None
    status = git("status", "--porcelain", "--untracked-files=no")
    return commit, (None if status is None else bool(status))


def provenance(
    scenario: Scenario | None, checkpoint: str | os.PathLike[str] | None = None
) -> dict[str, Any]:
    """The provenance fields (:data:`FIELDS`) of a result of ``scenario`` made with the
    controller checkpoint file ``checkpoint`` (``None``: no controller involved)."""
    commit, dirty = git_state()
    return {
        "scenario": None if scenario is None else scenario.name,
        "scenario_sha256": None if scenario is None else scenario_digest(scenario),
        "checkpoint_sha256": None if checkpoint is None else file_sha256(checkpoint),
        "hopnav_version": package_version(),
        "git_commit": commit,
        "git_dirty": dirty,
    }


def as_text(record: Mapping[str, Any]) -> dict[str, str]:
    """``record`` with every value as text (``""`` for ``None``), for PNG text chunks and
    CSV columns."""
    out = {}
    for key, value in record.items():
        if value is None:
            out[key] = ""
        elif isinstance(value, bool):
            out[key] = "true" if value else "false"
        else:
            out[key] = str(value)
    return out


def require_same_scenario(
    found: Mapping[str, Any] | None, expected: Mapping[str, Any], what: str
) -> None:
    """Refuse a result (``found``: its provenance) of another scenario than ``expected``.

    Raises:
        ProvenanceError: ``found`` has no ``scenario_sha256``, or another one; the message
            names ``what`` (e.g. the file) and both scenarios.
    """
    digest = found.get("scenario_sha256") if isinstance(found, Mapping) else None
    if not digest or not isinstance(digest, str):
        raise ProvenanceError(
            f"{what} carries no scenario digest (written by an older hopnav?), so it cannot "
            f"be matched to scenario {expected.get('scenario')!r}; use another file"
        )
    if digest != expected.get("scenario_sha256"):
        raise ProvenanceError(
            f"{what} belongs to scenario {found.get('scenario')!r} (digest {digest[:12]}), not "
            f"to this scenario {expected.get('scenario')!r} (digest "
            f"{str(expected.get('scenario_sha256'))[:12]}); use another file"
        )
