"""Bounds on one LTL translation, so that a hard formula fails fast instead of hanging.

A translation may take time and memory exponential in the formula (``F p1 & ... & F p12``
has 4096 states over 4096 letters). :class:`TranslationLimits` bounds

* the letters ``2^|AP|`` (checked before anything is built),
* the states of every automaton built on the way (tableau, progression, Safra, products;
  counted as each state is numbered, :func:`planner.ltl.interning.intern`), and the
  entries ``states x letters`` of its transition table,
* the wall-clock seconds (checked every :data:`_CHECK_EVERY` steps of work: numbered
  transitions, tableau expansions, DNF terms).

Exceeding one raises :class:`planner.errors.TranslationLimitError` naming the quantity and
the limit. :func:`translate` installs the limits for the duration of one call
(:func:`limited`); the construction functions call :func:`tick` and :func:`count_state`,
which do nothing outside a translation.
"""

from __future__ import annotations

import contextvars
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass

from planner.errors import TranslationLimitError

_CHECK_EVERY = 1024


@dataclass(frozen=True)
class TranslationLimits:
    """Limits of one translation.

    Attributes:
        max_letters: most letters ``2^|AP|`` of the alphabet (``2^16``: 16 propositions).
        max_states: most states of any automaton built during the translation.
        max_seconds: most wall-clock seconds (``None``: no time limit).
        max_entries: most entries ``states x letters`` of any transition table built.
    """

    max_letters: int = 1 << 16
    max_states: int = 20_000
    max_seconds: float | None = 10.0
    max_entries: int = 1 << 22

    def __post_init__(self) -> None:
        if int(self.max_letters) != self.max_letters or self.max_letters < 2:
            raise ValueError(f"max_letters must be a whole number >= 2, got {self.max_letters}")
        if int(self.max_states) != self.max_states or self.max_states < 1:
            raise ValueError(f"max_states must be a whole number >= 1, got {self.max_states}")
        if int(self.max_entries) != self.max_entries or self.max_entries < 2:
            raise ValueError(f"max_entries must be a whole number >= 2, got {self.max_entries}")
        if self.max_seconds is not None and not self.max_seconds > 0:
            raise ValueError(f"max_seconds must be > 0 or None, got {self.max_seconds}")

    def check_letters(self, n_propositions: int) -> None:
        """Raise :class:`TranslationLimitError` if ``2^n_propositions > max_letters``."""
        if n_propositions >= 63 or (1 << n_propositions) > self.max_letters:
            raise TranslationLimitError(
                f"{n_propositions} propositions make 2^{n_propositions} letters, more than "
                f"the limit of {self.max_letters} letters (raise it with --max-letters)"
            )


class _Budget:
    __slots__ = ("deadline", "letters", "limits", "next_check", "work")

    def __init__(self, limits: TranslationLimits) -> None:
        self.limits = limits
        self.letters = 1
        self.work = 0
        self.next_check = _CHECK_EVERY
        self.deadline = (
            None if limits.max_seconds is None else time.monotonic() + limits.max_seconds
        )


_ACTIVE: contextvars.ContextVar[_Budget | None] = contextvars.ContextVar(
    "planner_ltl_budget", default=None
)


@contextmanager
def limited(limits: TranslationLimits) -> Iterator[None]:
    """Apply ``limits`` to the translation work done inside the block."""
    token = _ACTIVE.set(_Budget(limits))
    try:
        yield
    finally:
        _ACTIVE.reset(token)


def tick(units: int = 1) -> None:
    """Count ``units`` steps of work; checks the clock every :data:`_CHECK_EVERY` steps."""
    b = _ACTIVE.get()
    if b is None:
        return
    b.work += units
    if b.work >= b.next_check:
        b.next_check = b.work + _CHECK_EVERY
        if b.deadline is not None and time.monotonic() > b.deadline:
            raise TranslationLimitError(
                f"the translation took longer than {b.limits.max_seconds:g} s (the limit; "
                "raise it with --max-seconds, or simplify the formula)"
            )


def set_letters(n_letters: int) -> None:
    """The letters of the automata built from now on (for the table-size limit)."""
    b = _ACTIVE.get()
    if b is not None:
        b.letters = int(n_letters)


def count_state(n_states: int, n_letters: int | None = None) -> None:
    """Check that an automaton under construction with ``n_states`` states (over
    ``n_letters`` letters, default: those of :func:`set_letters`) is within the limits."""
    b = _ACTIVE.get()
    if b is None:
        return
    if n_states > b.limits.max_states:
        raise TranslationLimitError(
            f"the translation built an automaton of more than {b.limits.max_states} states "
            "(the limit; raise it with --max-states, or simplify the formula)"
        )
    letters = b.letters if n_letters is None else n_letters
    if n_states * letters > b.limits.max_entries:
        raise TranslationLimitError(
            f"the translation built a transition table of {n_states} states x {letters} "
            f"letters, more than the limit of {b.limits.max_entries} entries (use fewer "
            "propositions, or simplify the formula)"
        )
