"""Files and tables of a sweep: raw-rows and summary CSV, Table I in Markdown and as text.

Every file is written atomically (a temporary file in the same folder, then ``os.replace``),
so a reader sees either the previous file or the complete new one. Floats are written with
``repr`` (they read back exactly); ``None`` is an empty field. Given a provenance record
(:func:`hopper_sim.experiments.provenance.provenance`), the CSVs end with one column per field (the
same
value on every row) and the Markdown table with a line naming them.
"""

from __future__ import annotations

import csv
import io
import math
from collections import Counter
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from hopper_sim.errors import HopperSimError
from hopper_sim.experiments.provenance import as_text
from hopper_sim.experiments.sweep import (
    ROW_COLUMNS,
    CellSummary,
    MeanCI,
    SweepResult,
    SweepRow,
    summary_record,
)
from hopper_sim.navigation.events import OUTCOMES
from planner._util.atomic import atomic_write
from planner._util.textfile import read_text

ROWS_FILE = "sweep_runs.csv"
SUMMARY_FILE = "sweep_summary.csv"
MARKDOWN_FILE = "table_i.md"


#: Largest sweep CSV read [bytes].
MAX_CSV_BYTES = 1 << 28


class SweepFileError(HopperSimError, ValueError):
    """A sweep CSV file is malformed; the message names the file, line and column."""


def _fmt_opt(value: object) -> str:
    # repr of a float reads back to the same float; None is an empty field
    if value is None:
        return ""
    return repr(value) if isinstance(value, float) else str(value)


def rows_csv(rows: Iterable[SweepRow], provenance: dict[str, Any] | None = None) -> str:
    """The raw rows as CSV text (header :data:`ROW_COLUMNS`, then the ``provenance`` fields;
    empty field for ``None``)."""
    extra = as_text(provenance or {})
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow([*ROW_COLUMNS, *extra])
    for r in rows:
        writer.writerow([*(_fmt_opt(getattr(r, name)) for name in ROW_COLUMNS), *extra.values()])
    return buf.getvalue()


SUMMARY_COLUMNS: tuple[str, ...] = (
    "c",
    "eps",
    "n",
    "reward_mean",
    "reward_ci_low",
    "reward_ci_high",
    "steps_mean",
    "steps_ci_low",
    "steps_ci_high",
    "success_rate",
    *(f"n_{o}" for o in OUTCOMES),
    "paper_reward",
    "paper_steps",
)


def summary_csv(cells: Iterable[CellSummary], provenance: dict[str, Any] | None = None) -> str:
    """Per-cell summaries as CSV text (header :data:`SUMMARY_COLUMNS`, then the ``provenance``
    fields; CIs at the sweep's level)."""
    extra = as_text(provenance or {})
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow([*SUMMARY_COLUMNS, *extra])
    for s in cells:
        rec = summary_record(s)
        writer.writerow([*(_fmt_opt(rec[k]) for k in SUMMARY_COLUMNS), *extra.values()])
    return buf.getvalue()


def _pm(ci: MeanCI, digits: int) -> str:
    if math.isnan(ci.mean):
        return "n/a"
    if math.isnan(ci.half_width):
        return f"{ci.mean:.{digits}f}"
    return f"{ci.mean:.{digits}f} ± {ci.half_width:.{digits}f}"


def _entry(s: CellSummary) -> str:
    return f"{_pm(s.reward, 1)} / {_pm(s.steps, 1)} ({s.successes}/{s.n})"


def _paper_entry(s: CellSummary) -> str:
    if s.paper is None:
        return "-"
    return f"{s.paper[0]:g}/{s.paper[1]:g}"


def _grid(result: SweepResult, entry: Callable[[CellSummary], str]) -> list[list[str]]:
    spec = result.spec
    head = ["P_RL,ee = C", *(f"eps = {e:g}" for e in spec.epss)]
    body = [[f"{c:g}", *(entry(result.cell(c, e)) for e in spec.epss)] for c in spec.cs]
    return [head, *body]


def _markdown_table(grid: list[list[str]]) -> str:
    lines = ["| " + " | ".join(grid[0]) + " |", "|" + "---|" * len(grid[0])]
    lines += ["| " + " | ".join(row) + " |" for row in grid[1:]]
    return "\n".join(lines)


def _level_pct(result: SweepResult) -> int:
    return round(100 * (result.cells[0].reward.level if result.cells else 0.95))


def markdown_table(result: SweepResult, provenance: dict[str, Any] | None = None) -> str:
    """Table I in Markdown: rows ``P_RL,ee = C``, columns ``eps``, then the paper's table, then
    a line with the ``provenance`` fields when given.

    An entry reads ``reward ± h / steps ± h (successes/runs)`` with ``h`` the half-width of
    the confidence interval.
    """
    level = _level_pct(result)
    has_paper = any(s.paper is not None for s in result.cells)
    parts = [
        f"## Table I as hopnav measured it (scenario {result.scenario})",
        "",
        f"Mean reward / mean steps over {result.spec.runs} runs per cell, ± the half-width of "
        f"the {level} % Student-t confidence interval; (successes/runs) in parentheses. "
        f"Base seed {result.spec.seed}.",
        "",
        _markdown_table(_grid(result, _entry)),
    ]
    if has_paper:
        parts += [
            "",
            "## Table I in the paper (reward/steps, mean of ten runs)",
            "",
            _markdown_table(_grid(result, _paper_entry)),
        ]
    if provenance:
        fields = "; ".join(f"{k} `{v}`" for k, v in as_text(provenance).items() if v)
        parts += ["", f"Provenance: {fields}."]
    return "\n".join(parts) + "\n"


def format_table(result: SweepResult) -> str:
    """A plain-text Table I for a terminal: measured entries beside the paper's."""

    def both(s: CellSummary) -> str:
        paper = "" if s.paper is None else f"  [paper {_paper_entry(s)}]"
        return _entry(s) + paper

    grid = _grid(result, both)
    widths = [max(len(row[k]) for row in grid) for k in range(len(grid[0]))]
    lines = [
        "  ".join(cell.ljust(w) for cell, w in zip(row, widths, strict=True)).rstrip()
        for row in grid
    ]
    lines.insert(1, "  ".join("-" * w for w in widths))
    level = _level_pct(result)
    title = (
        f"Table I, scenario {result.scenario}: reward / steps (± {level} % CI half-width), "
        f"(successes/runs); {result.spec.runs} runs per cell, seed {result.spec.seed}"
    )
    reasons = Counter(r.reason for r in result.rows if r.reason)
    if reasons:
        ended = ", ".join(f"{n} x {why}" for why, n in reasons.most_common())
        lines.append(f"runs ended by: {ended}")
    return "\n".join([title, *lines])


def atomic_write_text(path: str | Path, text: str) -> Path:
    """Write ``text`` to ``path`` atomically (:func:`planner._util.atomic.atomic_write`), creating
    its folder; ``path`` is either the old file or the complete new one."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(path, "w", fsync=True, newline="") as fh:
        fh.write(text)
    return path


def write_outputs(
    result: SweepResult, out_dir: str | Path, provenance: dict[str, Any] | None = None
) -> dict[str, Path]:
    """Write the raw rows CSV, the summary CSV and the Markdown table into ``out_dir``, each
    with the ``provenance`` fields when given.

    Returns:
        ``{"rows": ..., "summary": ..., "markdown": ...}``: the paths written.
    """
    out = Path(out_dir)
    return {
        "rows": atomic_write_text(out / ROWS_FILE, rows_csv(result.rows, provenance)),
        "summary": atomic_write_text(out / SUMMARY_FILE, summary_csv(result.cells, provenance)),
        "markdown": atomic_write_text(out / MARKDOWN_FILE, markdown_table(result, provenance)),
    }


# --------------------------------------------------------------------------- reading


def _parse_field(name: str, text: str) -> Any:
    if name in ("reason", "p_trace"):
        return text
    if name == "outcome":
        if text not in OUTCOMES:
            raise ValueError(f"must be one of {OUTCOMES}, got {text!r}")
        return text
    if name in ("switch_step", "p_switch"):
        if text == "":
            return None
        return int(text) if name == "switch_step" else float(text)
    if name in ("run", "seed", "steps", "backups"):
        return int(text)
    value = float(text)
    if not math.isfinite(value):
        raise ValueError(f"must be finite, got {text!r}")
    return value


_OPTIONAL = ("reason", "p_trace")


def read_rows_csv(path: str | Path) -> list[SweepRow]:
    """Read a raw-rows CSV written by :func:`write_outputs` (``sweep_runs.csv``).

    Extra columns are ignored; the columns of :data:`ROW_COLUMNS` must be present.

    Raises:
        SweepFileError: missing file, missing column or a bad value (names line and column).
    """
    path = Path(path)
    text = read_text(path, SweepFileError, MAX_CSV_BYTES)
    reader = csv.DictReader(io.StringIO(text))
    try:
        header = reader.fieldnames or []
        missing = [c for c in ROW_COLUMNS if c not in header and c not in _OPTIONAL]
        if missing:
            raise SweepFileError(
                f"{path}:1: missing column(s) {missing} (need {list(ROW_COLUMNS)})"
            )
        return _read_records(path, reader, header)
    except csv.Error as err:
        raise SweepFileError(f"{path}:{reader.line_num}: malformed CSV ({err})") from None


def _read_records(path: Path, reader: csv.DictReader, header: list[str]) -> list[SweepRow]:
    rows = []
    for record in reader:
        line = reader.line_num
        values = {}
        for name in ROW_COLUMNS:
            raw = record.get(name)
            if raw is None and name in _OPTIONAL and name not in header:
                continue
            if raw is None:
                raise SweepFileError(f"{path}:{line}: column '{name}': the line is too short")
            try:
                values[name] = _parse_field(name, raw.strip())
            except ValueError as err:
                raise SweepFileError(f"{path}:{line}: column '{name}': {err}") from err
        try:
            rows.append(SweepRow(**values))
        except (TypeError, ValueError) as err:
            raise SweepFileError(f"{path}:{line}: {err}") from None
    return rows
