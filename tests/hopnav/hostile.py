"""Hostile command-line cases for :mod:`tests.hopnav.test_fuzz_cli`: malformed, huge and
binary inputs to every command, as a careless or hostile user would give them.

A :class:`Case` is a command line run in an empty folder holding ``files`` (relative path ->
bytes, a callable returning bytes, or :data:`FOLDER`), with ``stdin`` bytes. Every case must
end in a clean error: exit code 1 or 2, one line on stderr (holding every string of
``says``), no traceback, nothing left behind. Cases named ``issue-...`` are the inputs listed
in the reliability issue (tracebacks, hangs, wrong successes), by their class; the others are
generated from fixed seeds (random bytes, truncations, deep nestings, bad numbers).
"""

from __future__ import annotations

import io
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

FOLDER = object()  # a file entry that is a folder
Content = bytes | str | Callable[[], bytes] | object


@dataclass(frozen=True)
class Case:
    name: str
    argv: tuple[str, ...]
    files: dict[str, Content] = field(default_factory=dict)
    stdin: bytes | None = None
    says: tuple[str, ...] = ()
    process: bool = False  # run as a subprocess (hangs, memory): timeout and peak RSS measured


# --------------------------------------------------------------------------- base inputs

TRA = "2 2 3\n0 0 0 [0.4,0.6] a\n0 0 1 [0.4,0.6] a\n1 0 1 [1,1] a\n"
LAB = '0="init" 1="goal"\n0: 0\n1: 1\n'
DRN = (
    "@type: MDP\n@value_type: double-interval\n@nr_states\n2\n@model\nstate 0 init\n"
    "\taction a\n\t\t0 : [0.4, 0.6]\n\t\t1 : [0.4, 0.6]\nstate 1 goal\n\taction a\n"
    "\t\t1 : [1, 1]\n"
)
BMDP = "2\n1\n1\n1\n0 0 0 0.4 0.6\n0 0 1 0.4 0.6\n1 0 1 1 1\n"
SCENARIO = """\
name = "tiny"
description = "A 6 x 4 m world."
formula = "{formula}"
reward_known = {known}

[world]
size = [{width}, {height}]
cell = {cell}

[initial]
rects = [[0.0, 1.0, 1.0, 3.0]]
start = [0.5, 1.5]

[regions.Goal]
rects = [[5.0, 0.0, 6.0, 4.0]]

[regions.Haz]
cells = [[3, 0]]

[regions.A]
cells = [[2, 3]]
{extra}
[rewards]
A = {reward}

[runner]
batch_size = 5
max_steps = 12
"""


def scenario(
    formula: str = "!Haz U Goal",
    *,
    width: float = 6.0,
    height: float = 4.0,
    cell: float = 1.0,
    reward: str = "5.0",
    extra: str = "",
    known: str = "true",
) -> str:
    return SCENARIO.format(
        formula=formula,
        width=width,
        height=height,
        cell=cell,
        reward=reward,
        extra=extra,
        known=known,
    )


def sweep_csv_header() -> str:
    from hopper_sim.experiments.sweep import ROW_COLUMNS

    return ",".join(ROW_COLUMNS) + "\n"


def shipped_checkpoint() -> bytes:
    from hopper_sim.controller.checkpoint import DEFAULT_CHECKPOINT

    return DEFAULT_CHECKPOINT.read_bytes()


def flipped(source: Callable[[], bytes], seed: int) -> Callable[[], bytes]:
    """``source`` with one random bit flipped."""

    def make() -> bytes:
        data = bytearray(source())
        rng = np.random.default_rng(seed)
        data[int(rng.integers(len(data)))] ^= 1 << int(rng.integers(8))
        return bytes(data)

    return make


def q_table() -> bytes:
    """A sealed Q-table (of no scenario in particular: its digest is checked first)."""
    import tempfile
    from pathlib import Path

    from planner.qlearning import RobustQLearner

    learner = RobustQLearner(6, 8, 3, state_cell=np.arange(6) % 3)
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "q.npz"
        learner.save(path, metadata={"provenance": {"scenario_sha256": "0" * 64}})
        return path.read_bytes()


def q_table_of(name: str) -> Callable[[], bytes]:
    """A Q-table learnt (no runs: fresh) on shipped scenario ``name``, with its provenance."""

    def make() -> bytes:
        import tempfile
        from pathlib import Path

        from hopper_sim.controller.checkpoint import DEFAULT_CHECKPOINT
        from hopper_sim.experiments.provenance import provenance
        from hopper_sim.navigation.runner import NavigationRunner
        from planner.scenario import load_scenario

        sc = load_scenario(name)
        runner = NavigationRunner(sc)
        with tempfile.TemporaryDirectory() as folder:
            path = Path(folder) / "q.npz"
            prov = provenance(sc, DEFAULT_CHECKPOINT)
            runner.learner.save(path, metadata={"provenance": prov})
            return path.read_bytes()

    return make


def random_bytes(seed: int, size: int = 512) -> bytes:
    """Random bytes that are never UTF-8 (a 0xFF byte is placed in them)."""
    rng = np.random.default_rng(seed)
    data = bytearray(rng.integers(0, 256, size=size, dtype=np.uint8).tobytes())
    data[int(rng.integers(size))] = 0xFF
    return bytes(data)


def truncated(text: str, seed: int, garbage: str) -> bytes:
    """``text`` cut at a random point, then a line that no reader accepts."""
    rng = np.random.default_rng(seed)
    cut = int(rng.integers(1, len(text)))
    return (text[:cut] + "\n" + garbage + "\n").encode()


# --------------------------------------------------------------------------- the cases


def issue_tracebacks() -> list[Case]:
    """The issue's 47 tracebacks, by class."""
    deep_scenario = scenario("(" * 500 + "Goal" + ")" * 500)
    toml3000 = scenario() + "deep = " + "[" * 3000 + "]" * 3000 + "\n"
    cases = [
        Case("issue-recursion-parens-400", ("automaton", "(" * 400 + "a" + ")" * 400)),
        Case("issue-recursion-parens-5000", ("automaton", "(" * 5000 + "a" + ")" * 5000)),
        Case("issue-recursion-not-1000", ("automaton", "!" * 1000 + "a")),
        Case("issue-recursion-next-1000", ("automaton", "X " * 1000 + "a")),
        Case("issue-recursion-until-2000", ("automaton", " U ".join(["a"] * 2001))),
        Case("issue-recursion-and-20000", ("automaton", "a & " * 20000 + "a")),
        Case(
            "issue-recursion-scenario-formula-500",
            ("scenario", "s.toml"),
            {"s.toml": deep_scenario},
        ),
        Case(
            "issue-recursion-run-formula-500",
            ("run", "--scenario", "s.toml"),
            {"s.toml": deep_scenario},
        ),
        Case("issue-recursion-toml-array-3000", ("scenario", "s.toml"), {"s.toml": toml3000}),
        Case(
            "issue-recursion-jsonl-array-100000",
            ("hop", "--jsonl"),
            stdin=b"[" * 100000 + b"]" * 100000 + b"\n",
        ),
        Case("issue-recursion-jsonl-array-30000", ("hop", "--jsonl"), stdin=b"[" * 30000 + b"\n"),
    ]
    latin1 = "caf\u00e9".encode("latin-1")
    binary = bytes(range(256)) * 4
    for fmt, name, text, extra in (
        ("prism", "m.tra", TRA, ("--target", "goal")),
        ("drn", "m.drn", DRN, ("--target", "goal")),
        ("bmdp", "m.bmdp", BMDP, ()),
    ):
        cases.append(
            Case(
                f"issue-unicode-{fmt}-latin1",
                ("imdp", "solve", name, *extra),
                {name: text.encode() + b"# " + latin1 + b"\n"},
                says=("not UTF-8", "byte"),
            )
        )
        cases.append(
            Case(f"issue-unicode-{fmt}-binary", ("imdp", "solve", name, *extra), {name: binary})
        )
    cases += [
        Case(
            "issue-unicode-lab-latin1",
            ("imdp", "solve", "m.tra", "--target", "goal"),
            {"m.tra": TRA, "m.lab": LAB.encode() + latin1},
            says=("m.lab", "not UTF-8"),
        ),
        Case(
            "issue-unicode-sweep-csv-resume",
            ("sweep", "--resume", "--out", "o", "--runs", "1", "--backend", "serial"),
            {"o/sweep_runs.csv": sweep_csv_header().encode() + latin1, "o/sweep_meta.json": "{}"},
        ),
        Case(
            "issue-unicode-sweep-csv-table-i",
            ("figure", "--table-i", "rows.csv", "--out", "f.png"),
            {"rows.csv": lambda: sweep_csv_header().encode() + latin1},
            says=("not UTF-8",),
        ),
        Case(
            "issue-unicode-scenario-latin1",
            ("scenario", "s.toml"),
            {"s.toml": scenario().encode() + b"# " + latin1},
        ),
        Case("issue-unbound-bmdp-binary", ("imdp", "solve", "m.bmdp"), {"m.bmdp": binary}),
        Case("issue-unbound-bmdp-directory", ("imdp", "solve", "m.bmdp"), {"m.bmdp": FOLDER}),
        Case(
            "issue-memory-prism-states-1e11",
            ("imdp", "solve", "m.tra", "--target", "goal"),
            {"m.tra": "100000000000 1 1\n0 0 0 1\n"},
            says=("limit",),
        ),
        Case(
            "issue-memory-bmdp-states-2e10",
            ("imdp", "solve", "m.bmdp"),
            {"m.bmdp": "20000000000\n1\n0\n"},
            says=("limit",),
        ),
        Case(
            "issue-memory-bmdp-actions-1e10",
            ("imdp", "solve", "m.bmdp"),
            {"m.bmdp": "2\n10000000000\n0\n"},
            says=("limit",),
        ),
        Case(
            "issue-memory-world-1e6m",
            ("scenario", "s.toml"),
            {"s.toml": scenario(width=1e6, height=1e6)},
            says=("limit",),
        ),
        Case(
            "issue-memory-cell-1e-4",
            ("scenario", "s.toml"),
            {"s.toml": scenario(cell=1e-4)},
            says=("limit",),
        ),
        Case(
            "issue-memory-world-1000m",
            ("run", "--scenario", "s.toml"),
            {"s.toml": scenario(width=1000.0, height=1000.0)},
            says=("limit",),
        ),
    ]
    for fmt, name, text, extra in (
        ("prism", "m.tra", "2 1 1\n0 0 100000000000000000000000 [1,1] a\n", ("--target", "goal")),
        (
            "drn",
            "m.drn",
            DRN.replace("\t\t1 : [1, 1]", "\t\t99999999999999999999999 : [1, 1]"),
            ("--target", "goal"),
        ),
        ("bmdp", "m.bmdp", BMDP.replace("1 0 1 1 1", "1 0 99999999999999999999999 1 1"), ()),
    ):
        cases.append(
            Case(
                f"issue-overflow-successor-{fmt}",
                ("imdp", "solve", name, *extra),
                {name: text},
                says=("successor",),
            )
        )
    huge = "B = 1.0e308\n"
    inf_scenario = scenario(reward="1.0e308", extra="[regions.B]\ncells = [[2, 3]]\n").replace(
        "A = 1.0e308", "A = 1.0e308\n" + huge
    )
    cases += [
        Case(
            "issue-product-reward-sums-to-inf",
            ("run", "--scenario", "s.toml"),
            {"s.toml": inf_scenario},
            says=("rewards",),
        ),
        Case(
            "issue-product-reward-sums-to-inf-export",
            ("imdp", "export", "--scenario", "s.toml", "--out", "p.drn"),
            {"s.toml": inf_scenario},
        ),
        Case("issue-sweep-cs-empty", ("sweep", "--cs", "", "--backend", "process")),
        Case("issue-sweep-out-existing-file", ("sweep", "--out", "f"), {"f": "x"}),
    ]
    for kind, text in (("list", "[1, 2]"), ("null", "null"), ("string", '"abc"')):
        cases.append(
            Case(
                f"issue-sweep-resume-meta-{kind}",
                ("sweep", "--resume", "--out", "o", "--runs", "1"),
                {"o/sweep_meta.json": text, "o/sweep_runs.csv": sweep_csv_header},
                says=("sweep_meta.json",),
            )
        )
    blocked = {"blocker": "a file where a folder should be"}
    for writer, argv in (
        ("imdp-export", ("imdp", "export", "m.bmdp", "--out", "{}/p.drn")),
        ("scenario-png", ("scenario", "a", "--png", "{}/w.png")),
        ("run-rrd", ("run", "--rrd", "{}/r.rrd", "--no-png")),
        ("run-png", ("run", "--png", "{}/r.png", "--no-rrd")),
    ):
        out = next(i for i, a in enumerate(argv) if "{}" in a)
        folder = argv[out].split("/")[-1]  # a folder named like the file to write
        files = {"m.bmdp": BMDP, folder: FOLDER, **blocked}
        as_dir = list(argv)
        as_dir[out] = folder
        cases.append(
            Case(f"issue-writer-{writer}-directory", tuple(as_dir), files, says=("folder",))
        )
        missing = list(argv)
        missing[out] = argv[out].format("blocker/missing")
        cases.append(
            Case(f"issue-writer-{writer}-missing-folder", tuple(missing), files, says=("blocker",))
        )
    cases.append(
        Case(
            "issue-checkpoint-corrupt",
            ("run", "--checkpoint", "c.pt", "--no-rrd", "--no-png"),
            {"c.pt": flipped(shipped_checkpoint, 7)},
            says=("--checkpoint", "c.pt"),
        )
    )
    return cases


def issue_hangs() -> list[Case]:
    """The issue's 4 hangs (run as subprocesses with a time limit)."""
    return [
        Case(
            "issue-hang-automaton-24-props",
            ("automaton", " & ".join(f"p{i}" for i in range(24))),
            says=("letters",),
            process=True,
        ),
        Case(
            "issue-hang-automaton-100-props",
            ("automaton", " & ".join(f"p{i}" for i in range(100))),
            says=("letters",),
            process=True,
        ),
        Case(
            "issue-hang-automaton-12-F",
            ("automaton", " & ".join(f"F p{i}" for i in range(12))),
            says=("limit",),
            process=True,
        ),
        Case(
            "issue-hang-drn-nr-states-2e10",
            ("imdp", "solve", "h.drn", "--target", "goal"),
            {"h.drn": "@type: MDP\n@nr_states\n20000000000\n@model\n"},
            says=("limit",),
            process=True,
        ),
    ]


def issue_wrong_successes() -> list[Case]:
    """The issue's 7 wrong successes."""
    return [
        Case("issue-success-ap-keyword-U", ("automaton", "a", "--ap", "a", "U"), says=("'U'",)),
        Case("issue-success-ap-empty-name", ("automaton", "a", "--ap", "a", ""), says=("''",)),
        Case(
            "issue-success-ap-quote", ("automaton", "a", "--ap", "a", 'b"c'), says=("plain name",)
        ),
        Case(
            "issue-success-ap-newline",
            ("automaton", "a", "--ap", "a", "b\nc"),
            says=("plain name",),
        ),
        Case("issue-success-dotted-identifier", ("automaton", "a.b U c"), says=("'.'",)),
        Case(
            "issue-success-bmdp-n-terminal-negative",
            ("imdp", "solve", "m.bmdp"),
            {"m.bmdp": "2\n1\n-1\n0 0 0 1 1\n1 0 1 1 1\n"},
            says=("negative",),
        ),
        Case(
            "issue-success-ap-42-names",
            ("automaton", "p0", "--ap", *(f"p{i}" for i in range(42))),
            says=("letters",),
        ),
    ]


def issue_other_classes() -> list[Case]:
    """The issue's other findings that are bad input: bit-flipped checkpoints and Q-tables,
    non-physical hops, results that would be overwritten."""
    cases = [
        Case(
            "issue-hop-speed-1e6",
            (
                "hop",
                "--json",
                "--pos",
                "0",
                "0",
                "--vel",
                "1e6",
                "0",
                "0",
                "--alpha",
                "1.2",
                "--beta",
                "0",
            ),
            says=("valid range",),
        ),
        Case(
            "issue-hop-noise-1e6",
            (
                "hop",
                "--vel",
                "4",
                "0",
                "-1",
                "--alpha",
                "1.2",
                "--beta",
                "0",
                "--noise",
                "1e6",
                "0",
            ),
            says=("valid range",),
        ),
        Case("issue-sweep-cs-comma", ("sweep", "--cs", ","), says=("--cs",)),
        Case(
            "issue-sweep-existing-results-without-resume",
            ("sweep", "--out", "o"),
            {"o/sweep_runs.csv": sweep_csv_header, "o/sweep_meta.json": "{}"},
            says=("--force",),
        ),
        Case(
            "issue-sweep-resume-grid-without-record",
            ("sweep", "--resume", "--out", "o"),
            {"o/sweep_meta.json": meta_for("a", None)},
            says=("grid",),
        ),
        Case(
            "issue-imdp-export-foreign-lab",
            ("imdp", "export", "m.bmdp", "--out", "x.tra"),
            {"m.bmdp": BMDP, "x.lab": LAB},
            says=("x.lab",),
        ),
        Case(
            "issue-q-table-known-reward",
            ("run", "--scenario", "a", "--q-table", "q.npz", "--no-rrd", "--no-png"),
            {"q.npz": q_table},
            says=("known reward",),
        ),
        Case(
            "issue-q-table-c-for-d",
            ("run", "--scenario", "d", "--q-table", "q.npz", "--no-rrd", "--no-png"),
            {"q.npz": q_table_of("c")},
            says=("belongs to scenario 'c'",),
        ),
        Case(
            "issue-checkpoint-weight-1.36e38",
            ("run", "--checkpoint", "c.pt", "--no-rrd", "--no-png"),
            {"c.pt": huge_weight_checkpoint},
            says=("plausible magnitude",),
        ),
    ]
    for k in range(12):
        cases.append(
            Case(
                f"issue-checkpoint-bit-flip-{k}",
                ("run", "--checkpoint", "c.pt", "--no-rrd", "--no-png"),
                {"c.pt": flipped(shipped_checkpoint, 100 + k)},
                says=("c.pt",),
            )
        )
    for k in range(6):
        cases.append(
            Case(
                f"issue-q-table-bit-flip-{k}",
                ("run", "--scenario", "c", "--q-table", "q.npz", "--no-rrd", "--no-png"),
                {"q.npz": flipped(q_table, 200 + k)},
                says=("q.npz",),
            )
        )
    for what, grid in (
        ("grid", '{"cs": [0.25], "epss": [0.005], "runs": 1, "seed": 0}'),
        ("seed", '{"cs": [0.5], "epss": [0.005], "runs": 1, "seed": 3}'),
        ("runs", '{"cs": [0.5], "epss": [0.005], "runs": 2, "seed": 0}'),
    ):
        cases.append(
            Case(
                f"issue-sweep-resume-other-{what}",
                (
                    "sweep",
                    "--resume",
                    "--out",
                    "o",
                    "--cs",
                    "0.5",
                    "--epss",
                    "0.005",
                    "--runs",
                    "1",
                ),
                {"o/sweep_meta.json": meta_for("a", grid)},
                says=("another grid",),
            )
        )
    cases.append(
        Case(
            "issue-sweep-resume-other-scenario",
            ("sweep", "--resume", "--out", "o", "--scenario", "b", "--runs", "1"),
            {"o/sweep_meta.json": meta_for("a", '{"cs": [0.5]}')},
            says=("belongs to scenario 'a'",),
        )
    )
    return cases


def meta_for(name: str, grid: str | None) -> Callable[[], bytes]:
    """A ``sweep_meta.json`` of shipped scenario ``name`` with ``grid`` (JSON text)."""

    def make() -> bytes:
        import json

        from hopper_sim.controller.checkpoint import DEFAULT_CHECKPOINT
        from hopper_sim.experiments.provenance import provenance
        from planner.scenario import load_scenario

        prov = provenance(load_scenario(name), DEFAULT_CHECKPOINT)
        record = {**prov, "provenance": prov}
        if grid is not None:
            record["grid"] = json.loads(grid)
        return json.dumps(record).encode()

    return make


def huge_weight_checkpoint() -> bytes:
    """The shipped checkpoint with one weight set to 1.36e38, sealed again (a valid digest)."""
    import torch

    from hopper_sim.controller.checkpoint import SEAL_KIND
    from planner._util.sealed import seal, unseal

    payload = torch.load(io.BytesIO(unseal(shipped_checkpoint(), SEAL_KIND)), weights_only=True)
    payload["state_dict"]["trunk.2.weight"][3, 7] = 1.36e38
    buf = io.BytesIO()
    torch.save(payload, buf)
    return seal(SEAL_KIND, buf.getvalue())


def generated() -> list[Case]:
    """Cases generated from fixed seeds, across every command."""
    cases: list[Case] = []
    rng = np.random.default_rng(18)
    # deep nestings of every kind, beyond the parser's limit of 100
    shapes = {
        "parens": lambda d: "(" * d + "a" + ")" * d,
        "not": lambda d: "!" * d + "a",
        "prefix": lambda d: "".join(rng.choice(["X ", "F ", "G ", "! "], size=d)) + "a",
        "until": lambda d: " U ".join(["a", "b"] * (d // 2 + 1)),
        "implies": lambda d: " -> ".join(["a"] * (d + 1)),
        "xor": lambda d: " xor ".join(["a"] * (d + 1)),
        "release": lambda d: "".join("(a R " for _ in range(d)) + "b" + ")" * d,
        "mixed": lambda d: "".join(rng.choice(["(", "!", "X ", "a U ", "a -> "], size=d)) + "a",
    }
    for name, make in shapes.items():
        for depth in (101, 700, 3000):
            cases.append(Case(f"ltl-deep-{name}-{depth}", ("automaton", make(depth))))
    # token soups that end in a dangling operator (never a formula)
    vocab = [
        "a",
        "b",
        "Goal",
        "(",
        ")",
        "&",
        "|",
        "!",
        "U",
        "R",
        "X",
        "F",
        "G",
        "->",
        "<->",
        "xor",
        "true",
        "1",
        "W",
        "M",
        "[]",
        "<>",
    ]
    for k in range(30):
        soup = " ".join(rng.choice(vocab, size=int(rng.integers(1, 200))))
        cases.append(Case(f"ltl-soup-{k}", ("automaton", soup + " &")))
    for k, char in enumerate("§$%@#?;:,.=+*/\\'`\u00e9\u4e2d\x01"):
        cases.append(Case(f"ltl-bad-character-{k}", ("automaton", f"a U {char}b")))
    long = " | ".join(f"p{i % 5}" for i in range(6000))
    cases.append(Case("ltl-too-many-tokens", ("automaton", long), says=("tokens",)))
    cases.append(
        Case(
            "ltl-17-propositions",
            ("automaton", " | ".join(f"p{i}" for i in range(17))),
            says=("letters",),
        )
    )
    cases.append(
        Case(
            "ltl-hard-with-max-seconds",
            (
                "automaton",
                "".join("(a U " if i % 2 else "(b R " for i in range(20)) + "c" + ")" * 20,
                "--max-seconds",
                "0.5",
            ),
            says=("--max-seconds",),
        )
    )
    cases.append(
        Case(
            "ltl-hard-with-max-states",
            (
                "automaton",
                " & ".join(f"(G F p{i} | F G q{i})" for i in range(5)),
                "--max-states",
                "5",
            ),
            says=("--max-states",),
        )
    )
    for value in ("0", "-1", "nan", "inf", "1e400", "", "x"):
        cases.append(
            Case(f"ltl-max-seconds-{value or 'empty'}", ("automaton", "a", "--max-seconds", value))
        )
    for flag, value in (
        ("--max-states", "0"),
        ("--max-states", "1e9"),
        ("--max-letters", "1"),
        ("--max-letters", "-5"),
    ):
        cases.append(Case(f"ltl-{flag[2:]}-{value}", ("automaton", "a", flag, value)))
    for word in (
        "X",
        "F",
        "G",
        "U",
        "R",
        "V",
        "W",
        "M",
        "xor",
        "true",
        "false",
        "GF",
        "XX",
        "9a",
        "a b",
        "a-b",
        "\u00e9",
    ):
        cases.append(Case(f"ltl-ap-name-{word!r}", ("automaton", "a", "--ap", "a", word)))
    cases.append(
        Case("ltl-ap-duplicate", ("automaton", "a", "--ap", "a", "a"), says=("duplicate",))
    )
    # model files: random bytes, truncations, hostile headers
    formats = (
        ("prism", "m.tra", TRA, ("--target", "goal")),
        ("drn", "m.drn", DRN, ("--target", "goal")),
        ("bmdp", "m.bmdp", BMDP, ()),
    )
    for fmt, name, text, extra in formats:
        for k in range(8):
            cases.append(
                Case(
                    f"model-{fmt}-random-{k}",
                    ("imdp", "solve", name, *extra),
                    {name: random_bytes(1000 + k)},
                )
            )
            cases.append(
                Case(
                    f"model-{fmt}-truncated-{k}",
                    ("imdp", "solve", name, *extra),
                    {name: truncated(text, 2000 + k, "? ?")},
                )
            )
        cases.append(Case(f"model-{fmt}-empty", ("imdp", "solve", name, *extra), {name: b""}))
        cases.append(
            Case(
                f"model-{fmt}-export-random",
                ("imdp", "export", name, "--out", "o.drn"),
                {name: random_bytes(3000)},
            )
        )
        cases.append(Case(f"model-{fmt}-missing", ("imdp", "solve", name, *extra)))
    for k, head in enumerate(
        ("-1 1 1", "2 -1 1", "2 1 -1", "1e3 1 1", "99999999999999999999 1 1", "2 2")
    ):
        cases.append(
            Case(
                f"model-prism-header-{k}",
                ("imdp", "solve", "m.tra", "--target", "goal"),
                {"m.tra": head + "\n0 0 0 1\n"},
            )
        )
    for k, head in enumerate(
        ("-2\n1\n0", "2\n-1\n0", "2\n1\n99999999", "2\n70000\n0", "nan\n1\n0", "2\n1\n1\n7")
    ):
        cases.append(
            Case(
                f"model-bmdp-header-{k}",
                ("imdp", "solve", "m.bmdp"),
                {"m.bmdp": head + "\n0 0 0 1 1\n"},
            )
        )
    for k, line in enumerate(
        (
            "-1 0 0 1 1",
            "0 -1 0 1 1",
            "0 0 -1 1 1",
            "5 0 0 1 1",
            "0 99999 0 1 1",
            "0 0 0 nan nan",
            "0 0 0 2 3",
            "0 0 0 0.9 0.1",
        )
    ):
        cases.append(
            Case(
                f"model-bmdp-line-{k}",
                ("imdp", "solve", "m.bmdp"),
                {"m.bmdp": "2\n1\n0\n" + line + "\n1 0 1 1 1\n"},
            )
        )
    for k, body in enumerate(
        (
            "@nr_states\n-3\n@model\n",
            "@nr_states\nx\n",
            "@model\n",
            "@:\n@nr_states\n1\n@model\nstate 0\n",
            "@nr_states\n1\n@model\nstate 5\n",
            "@nr_states\n1\n@model\naction a\n",
        )
    ):
        cases.append(
            Case(
                f"model-drn-body-{k}",
                ("imdp", "solve", "m.drn", "--target", "goal"),
                {"m.drn": body},
            )
        )
    for k, lab in enumerate(
        ("", "garbage\n", '0="init"\n9: 0\n', '0="init"\n0: 7\n', '0="init"\nx: 0\n')
    ):
        cases.append(
            Case(
                f"model-lab-{k}",
                ("imdp", "solve", "m.tra", "--target", "goal"),
                {"m.tra": TRA, "m.lab": lab},
            )
        )
    cases.append(Case("model-unknown-suffix", ("imdp", "solve", "m.txt"), {"m.txt": BMDP}))
    cases.append(
        Case(
            "model-export-unknown-out-suffix",
            ("imdp", "export", "m.bmdp", "--out", "o.xyz"),
            {"m.bmdp": BMDP},
        )
    )
    cases.append(
        Case(
            "model-solve-tolerance-nan",
            ("imdp", "solve", "m.bmdp", "--tolerance", "nan"),
            {"m.bmdp": BMDP},
        )
    )
    # scenarios, through every command that reads one
    bad_scenarios = {
        "random": random_bytes(4000),
        "truncated": truncated(scenario(), 4001, "= ="),
        "empty": b"",
        "not-toml": b"this is not toml",
        "regions-65": scenario(
            extra="".join(f"[regions.R{i}]\ncells = [[1, 1]]\n" for i in range(65))
        ),
        "rects-5000": scenario(
            extra="[regions.B]\nrects = [" + ", ".join(["[1.0, 1.0, 2.0, 2.0]"] * 5000) + "]\n"
        ),
        "formula-17-props": scenario(
            " | ".join(f"R{i}" for i in range(17)),
            extra="".join(f"[regions.R{i}]\ncells = [[1, 1]]\n" for i in range(17)),
        ),
        "reward-huge": scenario(reward="1e9"),
        "reward-nan": scenario(reward="nan"),
        "world-nan": scenario(width="nan"),
        "world-negative": scenario(width=-6.0),
        "cell-zero": scenario(cell=0.0),
        "inline-table-deep": scenario() + "x = " + "{a = " * 200 + "1" + "}" * 200 + "\n",
        "formula-syntax": scenario("!Haz U"),
        "formula-undefined": scenario("!Haz U Nowhere"),
    }
    commands = {
        "scenario": lambda p: ("scenario", p),
        "run": lambda p: ("run", "--scenario", p, "--no-rrd", "--no-png"),
        "sweep": lambda p: ("sweep", "--scenario", p, "--runs", "1"),
        "figure": lambda p: ("figure", "--scenarios", p, "--out", "f.png"),
        "export": lambda p: ("imdp", "export", "--scenario", p, "--out", "p.drn"),
    }
    for k, (kind, text) in enumerate(bad_scenarios.items()):
        command = list(commands)[k % len(commands)]
        cases.append(
            Case(f"scenario-{kind}-via-{command}", commands[command]("s.toml"), {"s.toml": text})
        )
        if command != "scenario":
            cases.append(Case(f"scenario-{kind}", commands["scenario"]("s.toml"), {"s.toml": text}))
    cases.append(Case("scenario-folder", ("scenario", "s.toml"), {"s.toml": FOLDER}))
    cases.append(Case("scenario-missing", ("run", "--scenario", "nowhere.toml")))
    # sweep arguments and destinations
    for k, (flag, value) in enumerate(
        (
            ("--cs", "nan"),
            ("--cs", "1,,2"),
            ("--cs", "0.5,0.5"),
            ("--cs", "2"),
            ("--epss", "inf"),
            ("--epss", "-1"),
            ("--runs", "0"),
            ("--runs", "1000000000"),
            ("--seed", "-1"),
            ("--workers", "0"),
            ("--backend", "gpu"),
            ("--cs", "1e400"),
        )
    ):
        cases.append(Case(f"sweep-argument-{k}", ("sweep", flag, value)))
    cases.append(Case("sweep-force-and-resume", ("sweep", "--force", "--resume")))
    for kind, text in (
        ("number", "5"),
        ("bad-json", "{not json"),
        ("binary", random_bytes(5000)),
        ("empty", ""),
    ):
        cases.append(
            Case(
                f"sweep-resume-meta-{kind}",
                ("sweep", "--resume", "--out", "o"),
                {"o/sweep_meta.json": text, "o/sweep_runs.csv": sweep_csv_header},
            )
        )
    cases.append(
        Case(
            "sweep-resume-rows-without-meta",
            ("sweep", "--resume", "--out", "o"),
            {"o/sweep_runs.csv": sweep_csv_header},
        )
    )
    # writers and destinations of every command
    files = {"d": FOLDER, "blocker": "x", "m.bmdp": BMDP}
    for k, argv in enumerate(
        (
            ("run", "--rrd", "x.txt", "--no-png"),
            ("run", "--png", "x.gif", "--no-rrd"),
            ("scenario", "a", "--png", "w.bmp"),
            ("figure", "--table-i", "missing.csv", "--out", "f.png"),
            ("figure", "--out", "d"),
            ("figure", "--out", "blocker/f.png"),
            ("figure", "--out", "f.png", "--run", "0"),
            ("figure", "--out", "f.png", "--save-rrd", "blocker"),
            ("train-controller", "--out", "d"),
            ("train-controller", "--out", "blocker/c.pt"),
            ("train-controller", "--out", "c.txt"),
            ("train-controller", "--save-data", "d"),
            ("imdp", "export", "m.bmdp", "--out", "d"),
            ("imdp", "export", "m.bmdp", "--out", "blocker/p.tra"),
            ("sweep", "--out", "blocker/sub"),
        )
    ):
        cases.append(Case(f"writer-{k}-{argv[0]}", argv, files))
    # checkpoints, Q-tables, datasets, recordings, CSVs: corrupt in many ways
    for k in range(6):
        cases.append(
            Case(
                f"checkpoint-random-{k}",
                ("run", "--checkpoint", "c.pt", "--no-rrd", "--no-png"),
                {"c.pt": random_bytes(5000 + k, 4096)},
            )
        )
        cases.append(
            Case(
                f"checkpoint-truncated-{k}",
                ("run", "--checkpoint", "c.pt", "--no-rrd", "--no-png"),
                {"c.pt": truncate_source(shipped_checkpoint, 5100 + k)},
            )
        )
        cases.append(
            Case(
                f"q-table-random-{k}",
                ("run", "--scenario", "c", "--q-table", "q.npz", "--no-rrd", "--no-png"),
                {"q.npz": random_bytes(5200 + k)},
            )
        )
        cases.append(
            Case(
                f"recording-random-{k}",
                ("replay", "r.rrd", "--summary"),
                {"r.rrd": random_bytes(5300 + k, 2048)},
            )
        )
        cases.append(
            Case(
                f"figure-rrd-random-{k}",
                ("figure", "--rrd", "r.rrd", "--out", "f.png"),
                {"r.rrd": random_bytes(5400 + k, 2048)},
            )
        )
        cases.append(
            Case(
                f"dataset-random-{k}",
                ("train-controller", "--data", "d.npz", "--out", "c.pt"),
                {"d.npz": random_bytes(5500 + k)},
            )
        )
        cases.append(
            Case(
                f"table-i-random-{k}",
                ("figure", "--table-i", "rows.csv", "--out", "f.png"),
                {"rows.csv": random_bytes(5600 + k)},
            )
        )
        cases.append(
            Case(
                f"table-i-truncated-{k}",
                ("figure", "--table-i", "rows.csv", "--out", "f.png"),
                {"rows.csv": truncate_source(lambda: sweep_csv_header().encode(), 5700 + k, b"?")},
            )
        )
    for name, content in (("empty", b""), ("folder", FOLDER), ("text", b"hello")):
        cases.append(
            Case(
                f"checkpoint-{name}",
                ("run", "--checkpoint", "c.pt", "--no-rrd", "--no-png"),
                {"c.pt": content},
            )
        )
        cases.append(Case(f"recording-{name}", ("replay", "r.rrd"), {"r.rrd": content}))
        cases.append(
            Case(
                f"dataset-{name}",
                ("train-controller", "--data", "d.npz", "--out", "c.pt"),
                {"d.npz": content},
            )
        )
    cases.append(
        Case(
            "checkpoint-unsealed-v1",
            ("run", "--checkpoint", "c.pt", "--no-rrd", "--no-png"),
            {"c.pt": unsealed_checkpoint},
            says=("version 1",),
        )
    )
    cases.append(
        Case(
            "dataset-zip-of-text",
            ("train-controller", "--data", "d.npz", "--out", "c.pt"),
            {"d.npz": zip_of_text},
        )
    )
    # hop: bad numbers on the command line and on stdin
    base = ["--vel", "4", "0", "-1", "--alpha", "1.2", "--beta", "0"]
    for k, (i, value) in enumerate(
        ((1, "nan"), (1, "inf"), (3, "1"), (5, "0"), (5, "2"), (7, "100"), (7, "nan"), (2, "-80"))
    ):
        argv = list(base)
        argv[i] = value
        cases.append(Case(f"hop-argument-{k}", ("hop", "--json", *argv)))
    cases.append(Case("hop-position-1e300", ("hop", "--pos", "1e300", "0", *base)))
    cases.append(Case("hop-perturb-negative", ("hop", "--perturb", "-1", *base)))
    cases.append(Case("hop-missing-vel", ("hop", "--alpha", "1")))
    lines = [
        b'{"pos": [0, 0], "vel": [4, 0, -1], "alpha": 1.2, "beta": 0}\n\xe9\n',
        random_bytes(6000, 300) + b"\n",
        b'{"pos": [0, 0], "vel": [4, 0, -1], "alpha": 1.2, "beta": ' + b"9" * 5000 + b"}\n",
        b'{"pos": [0, 0], "vel": [4, 0, -1], "alpha": 1.2, "beta": 1' + b"0" * 400 + b"}\n",
        b'{"pos": [0, 0], "vel": [1e6, 0, -1], "alpha": 1.2, "beta": 0}\n',
        b'{"pos": [0, 0], "vel": [4, 0, -1], "alpha": 1.2, "beta": 0, "noise": [1e6, 0]}\n',
        b'{"pos": [0, 0], "vel": [4, 0, -1], "alpha": 1.2, "beta": 0, "perturb": -4}\n',
        b'{"pos": [[0, 0]], "vel": [4, 0, -1], "alpha": 1.2, "beta": 0}\n',
        b'{"pos": {"a": {"b": {"c": {"d": {"e": {"f": {"g": {"h": {"i": 1}}}}}}}}}}\n',
        b"[1, 2, 3]\n",
        b'{"pos": "x"}\n',
        b"not json\n",
        b"\x00\x00\x00\n",
        b'{"pos": [0, 0]' + b" " * 70000 + b"}\n",
    ]
    for k, data in enumerate(lines):
        cases.append(Case(f"hop-jsonl-{k}", ("hop", "--jsonl"), stdin=data))
    # train-controller sizes
    for k, argv in enumerate(
        (
            ("--samples", "1000000000000"),
            ("--samples", "99"),
            ("--hidden", "100000"),
            ("--hidden", ",".join(["4"] * 20)),
            ("--hidden", "0"),
            ("--hidden", "a,b"),
            ("--nthread", "1000000"),
            ("--torch-threads", "0"),
            ("--epochs", "0"),
            ("--nominal-speed", "nan"),
            ("--hop-length", "-1"),
            ("--seed", "-1"),
        )
    ):
        cases.append(Case(f"train-argument-{k}", ("train-controller", *argv, "--out", "c.pt")))
    # figure and run numbers
    for k, argv in enumerate(
        (
            ("run", "--runs", "0"),
            ("run", "--runs", "1e3"),
            ("run", "--max-steps", "-5"),
            ("run", "--seed", "99999999999999999999999999x"),
            ("run", "--explore-to", "nowhere"),
            ("figure", "--out", "f.png", "--runs", "0"),
            ("figure", "--out", "f.png", "--seed", "-2"),
            ("figure", "--out", "f.png", "--scenarios", ","),
            ("figure", "--out", "f.png", "--rrd", "missing.rrd"),
            ("replay", "missing.rrd"),
            ("nonexistent-command",),
            ("--nonexistent-option",),
        )
    ):
        cases.append(Case(f"argument-{k}-{argv[0].strip('-')}", argv))
    return cases


def truncate_source(
    source: Callable[[], bytes], seed: int, tail: bytes = b""
) -> Callable[[], bytes]:
    def make() -> bytes:
        data = source()
        rng = np.random.default_rng(seed)
        return data[: int(rng.integers(1, len(data)))] + tail

    return make


def unsealed_checkpoint() -> bytes:
    from hopper_sim.controller.checkpoint import SEAL_KIND
    from planner._util.sealed import unseal

    return unseal(shipped_checkpoint(), SEAL_KIND)


def zip_of_text() -> bytes:
    import zipfile

    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        zf.writestr("inputs.npy", "not an array")
    return buf.getvalue()


def ring_model(n: int, n_labels: int) -> tuple[str, str]:
    """A PRISM ring of ``n`` states (to itself or the next, each [0.4, 0.6]) and labels
    ``p1..p{n_labels}`` spread over it: ``(tra, lab)``."""
    tra = [f"{n} {n} {2 * n}\n"]
    tra += [f"{s} 0 {s} [0.4,0.6]\n{s} 0 {(s + 1) % n} [0.4,0.6]\n" for s in range(n)]
    names = " ".join(f'{k}="p{k}"' for k in range(1, n_labels + 1))
    lab = [f'0="init" {names}\n0: 0\n'] + [f"{s}: {1 + s % n_labels}\n" for s in range(1, n)]
    return "".join(tra), "".join(lab)


def imdp_check_cases() -> list[Case]:
    """``hopnav imdp check`` (an LTL formula over a model file's labels): the formula's
    hostile forms, a translation or a product beyond the limits, broken files; a world
    beyond the cell limit for ``imdp export --scenario``."""
    files = {"m.tra": TRA, "m.lab": LAB}
    cases = [
        Case(f"imdp-check-{name}", ("imdp", "check", "m.tra", "--ltl", formula), files, says=says)
        for name, formula, says in (
            ("unknown-label", "F nowhere", ("nowhere",)),
            ("syntax", "F (goal", ()),
            ("empty", "", ()),
            ("nested-1000", "(" * 1000 + "goal" + ")" * 1000, ("nest",)),
            ("not-5000", "!" * 5000 + "goal", ("nest",)),
            ("tokens-30000", " & ".join(["goal"] * 15000), ("tokens",)),
            ("binary", "F \x00\x01", ()),
        )
    ]
    tra, lab = ring_model(20_000, 8)
    eight = " & ".join(f"F p{k}" for k in range(1, 9))  # 256 automaton states
    cases += [
        Case(
            "imdp-check-product-too-large",
            ("imdp", "check", "r.tra", "--ltl", eight),
            {"r.tra": tra, "r.lab": lab},
            says=("product", "5120000 states", "limit"),
        ),
        Case(
            "imdp-check-max-states",
            ("imdp", "check", "r.tra", "--ltl", eight, "--max-states", "100"),
            {"r.tra": tra, "r.lab": lab},
            says=("states",),
        ),
        Case(
            "imdp-check-max-seconds",
            ("imdp", "check", "m.tra", "--ltl", "F goal", "--max-seconds", "0"),
            files,
        ),
        Case(
            "imdp-check-binary-file",
            ("imdp", "check", "m.tra", "--ltl", "F goal"),
            {"m.tra": b"\xff\xfe\x00binary", "m.lab": LAB},
        ),
        Case("imdp-check-missing-file", ("imdp", "check", "none.tra", "--ltl", "F goal")),
        Case("imdp-check-no-ltl", ("imdp", "check", "m.tra"), files),
    ]
    cases += [
        Case("run-tour-unknown", ("run", "--tour", "nowhere")),
        Case(
            "imdp-export-world-256",
            ("imdp", "export", "--scenario", "w.toml", "--out", "p.drn"),
            {"w.toml": scenario(width=256, height=256)},
            says=("cells, more than the limit of 2048",),
        ),
    ]
    return cases


def settings_cases() -> list[Case]:
    """``--set`` on the commands that run the loop, and ``hopnav config``: the key named."""
    bad = [
        ("unknown", "switching.cc=1", "switching.cc: unknown key"),
        ("no-equals", "switching.c", "expected KEY=VALUE"),
        ("empty-key", "=1", "expected KEY=VALUE"),
        ("type", "delta=abc", "planner.delta: expected a number"),
        ("range", "delta=2", "planner.delta: delta must lie in (0, 1)"),
        ("discount", "discount=1", "planner.q_learning.discount"),
        ("p-sat", "p_sat=0", "planner.switching.p_sat"),
        ("bool", "env.noise=maybe", "env.noise: expected true or false"),
        ("int", "run.max_steps=2.5", "run.max_steps: expected a whole number"),
        ("choice", "tour=spiral", "planner.tour"),
        ("derived", "planner.noise=1", "planner.noise: derived"),
        ("gp", "gp.lengthscale=-1", "gp.lengthscale"),
        ("nan", "delta=nan", "planner.delta: must be a finite number"),
        ("huge", "run.max_steps=" + "9" * 5000, "run.max_steps"),
    ]
    cases = []
    for name, item, says in bad:
        for command in ("run", "sweep", "config"):
            extra = ("--out", "o") if command == "sweep" else ()
            cases.append(
                Case(f"set-{command}-{name}", (command, *extra, "--set", item), says=(says,))
            )
    cases += [
        Case("set-run-twice", ("run", "--set", "c=0.1", "--set", "c=0.2"), says=("given twice",)),
        Case(
            "set-run-and-flag",
            ("run", "--max-steps", "5", "--set", "run.max_steps=4"),
            says=("also given by --max-steps",),
        ),
        Case(
            "set-sweep-swept", ("sweep", "--out", "o", "--set", "c=0.3"), says=("the sweep sets",)
        ),
        Case("config-no-scenario", ("config", "--scenario", "nope.toml"), says=("nope.toml",)),
    ]
    return cases


def all_cases() -> list[Case]:
    cases = [
        *settings_cases(),
        *issue_tracebacks(),
        *issue_hangs(),
        *issue_wrong_successes(),
        *issue_other_classes(),
        *imdp_check_cases(),
        *generated(),
    ]
    names = [c.name for c in cases]
    assert len(set(names)) == len(names), sorted(n for n in names if names.count(n) > 1)
    return cases
