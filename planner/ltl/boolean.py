"""Two-level minimisation of Boolean functions given as sets of letters (bitmasks).

A letter over ``n`` propositions is an integer whose bit ``i`` is proposition ``i``. A
*cube* ``(care, value)`` is the conjunction of the literals ``p_i`` (bit ``i`` of ``value``
set) or ``!p_i`` (clear) for the bits ``i`` of ``care``.
"""

from __future__ import annotations


def prime_implicants(letters, n_props: int) -> list[tuple[int, int]]:
    """All prime implicants of the function true exactly on ``letters`` (Quine-McCluskey)."""
    full = (1 << n_props) - 1
    current = {(full, x) for x in letters}
    primes: set[tuple[int, int]] = set()
    while current:
        merged: set[tuple[int, int]] = set()
        used: set[tuple[int, int]] = set()
        by_mask: dict[int, set[int]] = {}
        for mask, val in current:
            by_mask.setdefault(mask, set()).add(val)
        for mask, vals in by_mask.items():
            for val in vals:
                for b in range(n_props):
                    bit = 1 << b
                    if mask & bit and not val & bit and (val | bit) in vals:
                        merged.add((mask & ~bit, val))
                        used.add((mask, val))
                        used.add((mask, val | bit))
        primes |= current - used
        current = merged
    return sorted(primes)


def _covers(cube: tuple[int, int], letter: int) -> bool:
    return letter & cube[0] == cube[1]


def cover(letters, n_props: int) -> list[tuple[int, int]]:
    """A small set of prime implicants covering ``letters`` (greedy set cover)."""
    todo = set(letters)
    primes = prime_implicants(todo, n_props)
    chosen = []
    while todo:
        best = max(primes, key=lambda c: (sum(_covers(c, x) for x in todo), -bin(c[0]).count("1")))
        chosen.append(best)
        todo = {x for x in todo if not _covers(best, x)}
    return sorted(chosen)
