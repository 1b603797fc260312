"""Files sealed with a digest of all their bytes: a one-line header, then the payload.

Layout::

    hopnav-sealed KIND sha256=HEX\\n
    PAYLOAD

with ``HEX`` the SHA-256 of ``KIND``, a NUL byte and ``PAYLOAD``. Every byte of the file is
covered: a changed payload byte changes the digest, a changed header byte breaks the header,
its kind or its digest. So a single flipped bit anywhere, a truncation or an appended tail
is detected before the payload is parsed (the payload's own format, a zip of ``torch.save``
or ``numpy.savez``, would load many such files silently).

:func:`seal` builds the bytes, :func:`unseal` checks them and returns the payload, raising
:class:`SealError`, which the callers turn into their own error type.
"""

from __future__ import annotations

import hashlib
import os
import re
from pathlib import Path

from planner.errors import SealError

MAGIC = b"hopnav-sealed"
_HEADER = re.compile(rb"hopnav-sealed ([a-z][a-z0-9-]{0,63}) sha256=([0-9a-f]{64})\n")
_MAX_HEADER = 160


def _digest(kind: bytes, payload: bytes) -> str:
    h = hashlib.sha256(kind)
    h.update(b"\0")
    h.update(payload)
    return h.hexdigest()


def seal(kind: str, payload: bytes) -> bytes:
    """``payload`` behind a header naming ``kind`` (lower-case letters, digits, ``-``) and
    the SHA-256 of both."""
    k = kind.encode("ascii")
    header = b"%s %s sha256=%s\n" % (MAGIC, k, _digest(k, payload).encode("ascii"))
    if _HEADER.fullmatch(header) is None:
        raise ValueError(f"invalid sealed-file kind {kind!r}")
    return header + payload


def is_sealed(data: bytes) -> bool:
    """Whether ``data`` starts like a sealed file (of any kind, intact or not)."""
    return data.startswith(MAGIC + b" ")


def unseal(data: bytes, kind: str) -> bytes:
    """The payload of sealed ``data`` of ``kind``.

    Raises:
        SealError: no intact header, another kind, or a digest that does not match.
    """
    end = data.find(b"\n", 0, _MAX_HEADER)
    m = _HEADER.fullmatch(data[: end + 1]) if end >= 0 else None
    if m is None:
        raise SealError("the header line 'hopnav-sealed KIND sha256=...' is missing or damaged")
    found = m.group(1).decode("ascii")
    if found != kind:
        raise SealError(f"it is a sealed {found!r} file, not {kind!r}")
    payload = data[end + 1 :]
    if _digest(m.group(1), payload) != m.group(2).decode("ascii"):
        raise SealError(
            "its contents do not match their SHA-256 digest (the file is corrupt or was "
            "changed after it was written)"
        )
    return payload


def read_limited(path: str | os.PathLike[str], limit: int) -> bytes:
    """The bytes of file ``path``, refusing (:class:`SealError`) a file larger than
    ``limit`` bytes before reading it.

    Raises:
        OSError: the file cannot be opened or read.
    """
    with open(Path(path), "rb") as f:
        size = os.fstat(f.fileno()).st_size
        if size > limit:
            raise SealError(f"the file holds {size} bytes, more than the limit of {limit}")
        data = f.read(limit + 1)
    if len(data) > limit:
        raise SealError(f"the file holds more than the limit of {limit} bytes")
    return data
