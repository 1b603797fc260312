"""Sealed files (:mod:`planner._util.sealed`): every single-bit flip, truncation and appended tail
is refused, exhaustively for a small file and for every header bit of the shipped
checkpoint (its payload bits are sampled in ``tests/hopper_sim/controller``)."""

from __future__ import annotations

import numpy as np
import pytest

from planner._util.sealed import SealError, is_sealed, read_limited, seal, unseal


def _flips(data: bytes, positions):
    """``data`` with one bit flipped, for every bit of every byte at ``positions``."""
    for pos in positions:
        for bit in range(8):
            flipped = bytearray(data)
            flipped[pos] ^= 1 << bit
            yield pos, bit, bytes(flipped)


def _refused(flipped: bytes, kind: str) -> bool:
    try:
        unseal(flipped, kind)
    except SealError:
        return True
    return False


def test_round_trip():
    payload = bytes(np.random.default_rng(0).integers(0, 256, 300, dtype=np.uint8))
    sealed = seal("q-table", payload)
    assert is_sealed(sealed) and unseal(sealed, "q-table") == payload
    assert unseal(seal("q-table", b""), "q-table") == b""


def test_every_single_bit_flip_of_a_small_file_is_refused():
    # the payload holds newlines and header-like bytes, so a flip can move the header's end
    payload = b"\n" + b"hopnav-sealed q-table sha256=" + bytes(range(256)) + b"\n\0"
    sealed = seal("q-table", payload)
    flips = _flips(sealed, range(len(sealed)))
    missed = [(p, b) for p, b, f in flips if not _refused(f, "q-table")]
    assert missed == [], missed[:10]


def test_every_single_bit_flip_of_the_shipped_checkpoint_header_is_refused():
    from hopper_sim.controller.checkpoint import DEFAULT_CHECKPOINT, SEAL_KIND

    data = DEFAULT_CHECKPOINT.read_bytes()
    header = data.index(b"\n") + 1
    assert unseal(data, SEAL_KIND)  # intact
    missed = [(p, b) for p, b, f in _flips(data, range(header)) if not _refused(f, SEAL_KIND)]
    assert missed == [], missed[:10]


def test_truncations_and_tails_are_refused():
    sealed = seal("hop-model-checkpoint", b"payload bytes " * 20)
    for end in range(len(sealed)):
        with pytest.raises(SealError):
            unseal(sealed[:end], "hop-model-checkpoint")
    for tail in (b"\0", b"\n", b"x" * 1000):
        with pytest.raises(SealError, match="digest"):
            unseal(sealed + tail, "hop-model-checkpoint")


def test_another_kind_is_refused():
    with pytest.raises(SealError, match="not 'q-table'"):
        unseal(seal("hop-model-checkpoint", b"x"), "q-table")


def test_invalid_kinds_cannot_be_sealed():
    for kind in ("", "Upper", "with space", "x" * 65, "new\nline"):
        with pytest.raises(ValueError, match="kind"):
            seal(kind, b"x")


def test_read_limited_refuses_a_larger_file_before_reading(tmp_path):
    path = tmp_path / "big"
    path.write_bytes(b"x" * 101)
    with pytest.raises(SealError, match="101 bytes, more than the limit of 100"):
        read_limited(path, 100)
    assert read_limited(path, 101) == b"x" * 101
