"""Line numbers of the keys of a TOML document.

``tomllib`` returns plain dicts with no positions. :func:`key_lines` scans the text once more
and maps every key to the 1-based line where it is written, so that a validation error found
in the parsed data can name its line. Keys are written as dotted paths with array indices:

- ``name`` for a top-level key, ``world.size`` for a key in ``[world]`` (or written
  ``world.size = ...`` at top level, or inside an inline table ``world = {size = ...}``);
- ``regions.Goal`` for a table header ``[regions.Goal]``;
- ``runs[2]`` for the third ``[[runs]]`` header, ``runs[2].seed`` for a key below it (and
  ``runs[2].sub`` for a later ``[runs.sub]`` header, which belongs to that entry);
- ``regions.Goal.rects[1]`` for the second element of an array, wherever it starts.

The scanner is meant for text that ``tomllib`` has already accepted; on text it cannot follow
it stops and returns what it found so far (it never raises).

:func:`nesting_depth` is meant for text *before* ``tomllib`` reads it: ``tomllib`` recurses
once per nested array or inline table, so a deeply nested value would end in a
``RecursionError``; the depth is measured without recursion first.
"""

from __future__ import annotations

import re

from planner.errors import PlannerError

_BARE = frozenset("ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789_-")


class _Stop(PlannerError):
    """The scanner cannot follow the text; caught in :func:`key_lines`, never escapes."""


class _Scanner:
    def __init__(self, text: str) -> None:
        self.text = text
        self.pos = 0
        self.line = 1
        self.lines: dict[str, int] = {}

    def peek(self, k: int = 1) -> str:
        return self.text[self.pos : self.pos + k]

    def advance(self, k: int = 1) -> None:
        chunk = self.text[self.pos : self.pos + k]
        self.line += chunk.count("\n")
        self.pos += k
        if self.pos > len(self.text):
            raise _Stop

    def record(self, path: str) -> None:
        self.lines.setdefault(path, self.line)

    def skip_blank(self, newlines: bool) -> None:
        """Skip spaces, tabs, comments and (when ``newlines``) line breaks."""
        while self.pos < len(self.text):
            c = self.text[self.pos]
            if c in " \t\r" or (newlines and c == "\n"):
                self.advance()
            elif c == "#":
                end = self.text.find("\n", self.pos)
                self.pos = len(self.text) if end < 0 else end
            else:
                return

    def key(self) -> list[str]:
        """A dotted key, as its parts."""
        parts = []
        while True:
            self.skip_blank(newlines=False)
            c = self.peek()
            if c in ('"', "'"):
                start = self.pos + 1
                self.string()
                parts.append(self.text[start : self.pos - 1])
            else:
                start = self.pos
                while self.pos < len(self.text) and self.text[self.pos] in _BARE:
                    self.pos += 1
                if self.pos == start:
                    raise _Stop
                parts.append(self.text[start : self.pos])
            self.skip_blank(newlines=False)
            if self.peek() != ".":
                return parts
            self.advance()

    def string(self) -> None:
        """Skip one string literal of any of TOML's four kinds."""
        for quote in ('"""', "'''"):
            if self.peek(3) == quote:
                self.advance(3)
                end = self.pos
                while True:
                    end = self.text.find(quote, end)
                    if end < 0:
                        raise _Stop
                    # A basic string may escape a quote; count the backslashes before it.
                    n_bs = 0
                    while quote == '"""' and self.text[end - 1 - n_bs] == "\\":
                        n_bs += 1
                    if n_bs % 2 == 0:
                        break
                    end += 1
                # Up to two extra quotes may close the string ("""a"""" is 'a"').
                extra = 0
                while extra < 2 and self.text[end + 3 : end + 4] == quote[0]:
                    end += 1
                    extra += 1
                self.advance(end + 3 - self.pos)
                return
        quote = self.peek()
        self.advance()
        while True:
            c = self.peek()
            if c in ("", "\n"):
                raise _Stop
            if c == "\\" and quote == '"':
                self.advance(2)
                continue
            self.advance()
            if c == quote:
                return

    def value(self, path: str) -> None:
        c = self.peek()
        if c == "[":
            self.advance()
            index = 0
            while True:
                self.skip_blank(newlines=True)
                if self.peek() == "]":
                    self.advance()
                    return
                element = f"{path}[{index}]"
                self.record(element)
                self.value(element)
                self.skip_blank(newlines=True)
                if self.peek() == ",":
                    self.advance()
                    index += 1
        elif c == "{":
            self.advance()
            while True:
                self.skip_blank(newlines=False)
                if self.peek() == "}":
                    self.advance()
                    return
                self.keyval(path)
                self.skip_blank(newlines=False)
                if self.peek() == ",":
                    self.advance()
        elif c in ('"', "'"):
            self.string()
        else:
            start = self.pos
            while self.pos < len(self.text) and self.text[self.pos] not in ",]}\n#":
                self.pos += 1
            if self.pos == start:
                raise _Stop

    def keyval(self, table: str) -> None:
        parts = self.key()
        path = table
        for part in parts:
            path = f"{path}.{part}" if path else part
            self.record(path)
        self.skip_blank(newlines=False)
        if self.peek() != "=":
            raise _Stop
        self.advance()
        self.skip_blank(newlines=False)
        self.value(path)

    def document(self) -> None:
        table = ""
        counts: dict[str, int] = {}  # resolved array-of-tables path -> number of entries

        def resolve(parts: list[str], upto: int) -> str:
            # A header inside an array of tables refers to its last entry: a[1].b
            path = ""
            for part in parts[:upto]:
                path = f"{path}.{part}" if path else part
                if path in counts:
                    path = f"{path}[{counts[path] - 1}]"
            return path

        while True:
            self.skip_blank(newlines=True)
            if self.pos >= len(self.text):
                return
            if self.peek(2) == "[[":
                self.advance(2)
                parts = self.key()
                self.skip_blank(newlines=False)
                if self.peek(2) != "]]":
                    raise _Stop
                for k in range(1, len(parts)):
                    self.record(resolve(parts, k))
                parent = resolve(parts, len(parts) - 1)
                name = f"{parent}.{parts[-1]}" if parent else parts[-1]
                self.record(name)
                index = counts.get(name, 0)
                counts[name] = index + 1
                table = f"{name}[{index}]"
                self.record(table)
                self.advance(2)
            elif self.peek() == "[":
                self.advance()
                parts = self.key()
                if self.peek() != "]":
                    raise _Stop
                for k in range(1, len(parts) + 1):
                    self.record(resolve(parts, k))
                table = resolve(parts, len(parts))
                self.advance()
            else:
                self.keyval(table)


# strings and comments are skipped whole; brackets and braces outside them counted
_NESTING = re.compile(
    r'''"""(?:[^"\\]|\\[\s\S]|"(?!""))*"""|\'\'\'[\s\S]*?\'\'\'|"(?:[^"\\\n]|\\.)*"'''
    r"""|'[^'\n]*'|#[^\n]*|[\[\]{}]"""
)


def nesting_depth(text: str) -> tuple[int, int]:
    """``(depth, line)``: the deepest nesting of ``[``/``{`` in TOML ``text`` (strings and
    comments skipped; a table header counts its brackets too) and the 1-based line where it
    is first reached. Linear time, no recursion."""
    depth = best = 0
    best_at = 0
    for m in _NESTING.finditer(text):
        c = m.group()
        if c in "[{":
            depth += 1
            if depth > best:
                best, best_at = depth, m.start()
        elif c in "]}":
            depth = max(depth - 1, 0)
    return best, text.count("\n", 0, best_at) + 1


def key_lines(text: str) -> dict[str, int]:
    """Map each dotted key path of the TOML ``text`` to its 1-based line (see module doc)."""
    scanner = _Scanner(text)
    try:
        scanner.document()
    except (_Stop, IndexError):
        pass
    return scanner.lines


def line_of(lines: dict[str, int], path: str) -> int | None:
    """The line of ``path``, else of its nearest enclosing key or table, else ``None``.

    ``regions.A.rects[1][0]`` falls back to ``regions.A.rects[1]``, ``regions.A.rects``,
    ``regions.A`` and ``regions``, in that order.
    """
    while path:
        if path in lines:
            return lines[path]
        cut = max(path.rfind("."), path.rfind("["))
        if cut <= 0:
            return None
        path = path[:cut]
    return None
