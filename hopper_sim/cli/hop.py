"""``hopnav hop``: simulate single hops and print the results (text or JSON).

``--json`` prints one JSON object for the hop given on the command line; ``--jsonl`` reads one
JSON case per line on stdin (keys ``pos``, ``vel``, ``alpha``, ``beta`` and optionally
``perturb`` (terrain seed), ``noise`` ([nx, ny] m), ``thrust`` (bool)) and writes one JSON
result per line. Without those options a hop is the pure SLIP. A failed hop is a result with
``"ok": false``; a malformed case is a result with status ``"invalid_input"`` and makes the
exit code 2.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
from collections.abc import Iterator
from typing import Any, TextIO

from hopnav.arguments import non_negative_int
from hopnav.errors import UsageError

INVALID_INPUT = "invalid_input"
#: Deepest nesting of arrays/objects in a JSON case (a case needs 2).
MAX_JSON_DEPTH = 8
#: Longest line read from stdin [bytes].
MAX_LINE_BYTES = 1 << 16
_JSON_TOKENS = re.compile(r'"(?:[^"\\]|\\.)*"|[\[\]{}]')


def _json_depth(text: str) -> int:
    """The deepest nesting of ``[``/``{`` in JSON ``text`` (strings skipped), without
    recursion (``json.loads`` recurses once per level)."""
    depth = best = 0
    for m in _JSON_TOKENS.finditer(text):
        c = m.group()
        if c in "[{":
            depth += 1
            best = max(best, depth)
        elif c in "]}":
            depth -= 1
    return best


def _stdin_lines() -> Iterator[tuple[int, str]]:
    """``(line number, text)`` of stdin, decoded strictly as UTF-8, lines of at most
    :data:`MAX_LINE_BYTES`; raises :class:`HopInputError` naming the line otherwise."""
    from hopper_sim.physics.hop import HopInputError
    from planner._util.textfile import decoded_lines

    buffer = getattr(sys.stdin, "buffer", None)
    if buffer is None:  # a text stream (tests): already decoded
        yield from enumerate(sys.stdin, start=1)
        return

    def raw_lines() -> Iterator[bytes]:
        while raw := buffer.readline(MAX_LINE_BYTES + 1):
            if len(raw) > MAX_LINE_BYTES and not raw.endswith(b"\n"):
                raise HopInputError(f"stdin: a line longer than {MAX_LINE_BYTES} bytes")
            yield raw

    yield from decoded_lines(raw_lines(), "stdin", HopInputError)


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "hop",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--pos", nargs=2, type=float, metavar=("X", "Y"), default=[0.0, 0.0])
    p.add_argument("--vel", nargs=3, type=float, metavar=("VX", "VY", "VZ"))
    p.add_argument("--alpha", type=float, help="leg elevation at touchdown [rad]")
    p.add_argument("--beta", type=float, help="leg azimuth from the velocity heading [rad]")
    p.add_argument(
        "--perturb", type=non_negative_int, metavar="SEED", help="terrain force field seed"
    )
    p.add_argument("--noise", nargs=2, type=float, metavar=("NX", "NY"), help="nu [m]")
    p.add_argument("--thrust", action="store_true", help="regulate energy to the start energy")
    out = p.add_mutually_exclusive_group()
    out.add_argument("--json", action="store_true", help="print the result as JSON")
    out.add_argument("--jsonl", action="store_true", help="read JSON cases from stdin")
    p.set_defaults(func=run)


class _Runner:
    def __init__(self) -> None:
        from hopper_sim.physics.model import HopperModel

        self.model = HopperModel.load()
        self.data = self.model.make_data()
        self.terrains: dict[int, Any] = {}

    def hop(self, case: dict[str, Any]) -> dict[str, Any]:
        import numpy as np

        from hopper_sim.physics.hop import HopInputError, simulate_hop
        from hopper_sim.physics.terrain import TerrainField

        seed = case.get("perturb")
        terrain = None
        if seed is not None:
            if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
                raise HopInputError(f"perturb must be a non-negative integer seed, got {seed!r}")
            if seed not in self.terrains:
                self.terrains[seed] = TerrainField.for_model(self.model, seed)
            terrain = self.terrains[seed]
        thrust = case.get("thrust", False)
        if not isinstance(thrust, bool):
            raise HopInputError(f"thrust must be true or false, got {thrust!r}")
        for key in ("pos", "vel", "alpha", "beta"):
            if key not in case:
                raise HopInputError(f"missing key {key!r}")
        try:
            pos = np.asarray(case["pos"], dtype=float)
            vel = np.asarray(case["vel"], dtype=float)
            alpha, beta = float(case["alpha"]), float(case["beta"])
            noise = None if case.get("noise") is None else np.asarray(case["noise"], dtype=float)
        except (TypeError, ValueError, OverflowError) as exc:
            raise HopInputError(f"non-numeric value: {exc}") from exc
        if pos.shape != (2,) or vel.shape != (3,):
            raise HopInputError(f"pos must have 2 and vel 3 numbers: {case['pos']}, {case['vel']}")
        result = simulate_hop(
            self.model,
            pos,
            vel,
            alpha,
            beta,
            terrain=terrain,
            noise=noise,
            thrust=thrust,
            record_path=False,
            data=self.data,
        )
        out = result.to_dict()
        out["perturb"] = seed
        out["thrust"] = thrust
        return out


def _invalid(message: str) -> dict[str, Any]:
    return {"ok": False, "status": INVALID_INPUT, "message": message}


def _clean(obj: Any) -> Any:
    """Replace non-finite floats by None so the output is strict JSON."""
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, list):
        return [_clean(x) for x in obj]
    if isinstance(obj, dict):
        return {k: _clean(v) for k, v in obj.items()}
    return obj


def _emit(result: dict[str, Any], stream: TextIO) -> None:
    stream.write(json.dumps(_clean(result), allow_nan=False) + "\n")
    stream.flush()


def _text(r: dict[str, Any]) -> str:
    if not r["ok"]:
        return f"hop failed: {r['status']}: {r['message']}"

    def v(xs: list[float]) -> str:
        return "[" + ", ".join(f"{x:.6f}" for x in xs) + "]"

    return "\n".join(
        [
            f"next_pos       {v(r['next_pos'])} m",
            f"next_vel       {v(r['next_vel'])} m/s",
            f"touchdown_time {r['touchdown_time']:.6f} s",
            f"liftoff_time   {r['liftoff_time']:.6f} s",
            f"flight_time    {r['flight_time']:.6f} s",
            f"foot           {v(r['foot'])} m",
            f"energy         {r['energy_before']:.6f} -> {r['energy_after']:.6f} J",
        ]
    )


def run(args: argparse.Namespace) -> int:
    from hopper_sim.physics.hop import HopInputError

    missing = [n for n in ("vel", "alpha", "beta") if getattr(args, n) is None]
    if missing and not args.jsonl:
        raise UsageError(f"missing --{', --'.join(missing)} (or use --jsonl)")
    runner = _Runner()
    if args.jsonl:
        invalid: list[str] = []
        lines = _stdin_lines()
        while True:
            try:
                lineno, line = next(lines)
            except StopIteration:
                break
            except HopInputError as exc:  # undecodable or too long: the rest is unreadable
                result = _invalid(str(exc))
                invalid.append(result["message"])
                _emit(result, sys.stdout)
                break
            if not line.strip():
                continue
            try:
                if _json_depth(line) > MAX_JSON_DEPTH:
                    raise HopInputError(f"JSON nested deeper than {MAX_JSON_DEPTH} levels")
                case = json.loads(line)
                if not isinstance(case, dict):
                    raise HopInputError("a case must be a JSON object")
                result = runner.hop(case)
            except ValueError as exc:  # JSONDecodeError, HopInputError, too many digits
                result = _invalid(f"line {lineno}: {exc}")
                invalid.append(result["message"])
            _emit(result, sys.stdout)
        if invalid:
            raise UsageError(
                f"{len(invalid)} invalid input line(s) on stdin, the first: {invalid[0]}"
            )
        return 0
    case: dict[str, Any] = {
        "pos": args.pos,
        "vel": args.vel,
        "alpha": args.alpha,
        "beta": args.beta,
        "perturb": args.perturb,
        "noise": args.noise,
        "thrust": args.thrust,
    }
    try:
        result = runner.hop(case)
    except HopInputError as exc:
        result = _invalid(str(exc))
        if args.json:
            _emit(result, sys.stdout)
        raise UsageError(str(exc)) from None
    if args.json:
        _emit(result, sys.stdout)
    else:
        print(_text(result))
    return 0
