"""The LTL translation is reproducible across processes: the same formula gives the same
automaton (state numbering, pairs, HOA text) whatever the hash seed, the memory layout or the
formulas translated before it in the process."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from tests.planner.ltl_oracle import PROPS, render
from tests.planner.test_ltl_translate import CORPUS

ROOT = Path(__file__).resolve().parents[2]

UNARY = ["!", "X", "F", "G"]
BINARY = ["&", "|", "->", "<->", "xor", "U", "R", "W", "M"]
LEAVES = [("ap", p) for p in PROPS]

#: A child process: reads formula texts, the alphabet and an allocation count (JSON on
#: stdin), allocates that many throw-away objects (shifting the addresses of everything
#: created later), then translates the formulas in the given order and prints, for each, the
#: HOA text (or the limit it exceeded; the bound keeps the test short) and whether it went
#: through the tableau / Safra construction.
CHILD = """
import importlib, json, sys
tr = importlib.import_module("planner.ltl.translate")
from planner.errors import TranslationLimitError
from planner.ltl.budget import TranslationLimits
from planner.ltl.hoa import to_hoa
limits = TranslationLimits(max_states=3000, max_seconds=None)
texts, props, n_junk = json.load(sys.stdin)
junk = [object() for _ in range(n_junk)]
safra = [0]
inner = tr._safra
def counted(*args):
    safra[0] += 1
    return inner(*args)
tr._safra = counted
out = {}
for t in texts:
    before = safra[0]
    try:
        hoa = to_hoa(tr.translate(t, props, limits))
    except TranslationLimitError as e:
        hoa = str(e)
    out[t] = [hoa, safra[0] > before]
json.dump(out, sys.stdout)
"""


def random_formula(rng: np.random.Generator, depth: int) -> tuple:
    """A random formula tree over :data:`PROPS` of nesting depth at most ``depth``."""
    kind = rng.integers(3) if depth > 0 else 0
    if kind == 0:
        return LEAVES[rng.integers(len(LEAVES))]
    if kind == 1:
        return (UNARY[rng.integers(len(UNARY))], random_formula(rng, depth - 1))
    op = BINARY[rng.integers(len(BINARY))]
    return (op, random_formula(rng, depth - 1), random_formula(rng, depth - 1))


def corpus() -> list[str]:
    """The translation tests' corpus and 80 random formulas: a fifth of them unshaped, the
    others shaped to go through the tableau / Safra construction with tableau states of
    several formulas (where the order of a state's formulas could leak into the result)."""
    rng = np.random.default_rng(20261202)

    def r(depth: int) -> tuple:
        return random_formula(rng, depth)

    shapes = [
        lambda: r(4),
        lambda: ("U", ("&", ("G", ("F", r(2))), ("X", r(2))), ("X", r(2))),
        lambda: ("U", ("&", ("G", ("F", r(2))), ("X", r(2))), ("X", r(2))),
        lambda: ("U", ("&", ("G", ("F", r(2))), r(2)), r(2)),
        lambda: ("W", ("&", ("G", ("F", r(2))), r(2)), r(2)),
    ]
    texts = [render(f) for f in CORPUS]
    while len(texts) < len(CORPUS) + 80:
        text = render(shapes[len(texts) % len(shapes)]())
        if text not in texts:
            texts.append(text)
    return texts


def translate_in_child(texts: list[str], hash_seed: str, n_junk: int) -> dict:
    env = {**os.environ, "PYTHONHASHSEED": hash_seed}
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")])
    done = subprocess.run(
        [sys.executable, "-c", CHILD],
        input=json.dumps([texts, PROPS, n_junk]),
        capture_output=True,
        text=True,
        env=env,
        cwd=ROOT,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout)


def test_translation_is_identical_across_processes():
    texts = corpus()
    first = translate_in_child(texts, "0", 0)
    # Other hash seed, other memory layout, other order (each formula translated after
    # different ones).
    second = translate_in_child(texts[::-1], "4242", 100_003)
    assert set(first) == set(second) == set(texts)
    through_safra = sum(first[t][1] for t in texts)
    assert through_safra >= 30, f"only {through_safra} formulas exercise the tableau/Safra path"
    differ = [t for t in texts if first[t] != second[t]]
    assert not differ, (
        f"{len(differ)} of {len(texts)} formulas translate differently in two processes, "
        f"first {differ[0]!r}:\n{first[differ[0]][0]}\nvs\n{second[differ[0]][0]}"
    )
