import os
import platform
import subprocess
import sys
import textwrap

import pytest

from planner import allocator

GLIBC = platform.system() == "Linux" and platform.libc_ver()[0] == "glibc"

# a 64 MiB block malloc'ed, touched, freed, then malloc'ed and touched again in a fresh
# process: the page faults of the second touch
_REFAULTS = textwrap.dedent(
    """
    import ctypes, ctypes.util, resource, sys
    from planner.allocator import reuse_freed_memory
    if sys.argv[1] == "reuse":
        assert reuse_freed_memory()
    libc = ctypes.CDLL(ctypes.util.find_library("c"))
    libc.malloc.restype = ctypes.c_void_p
    libc.malloc.argtypes = (ctypes.c_size_t,)
    libc.free.argtypes = (ctypes.c_void_p,)
    n = 64 << 20
    block = libc.malloc(n)
    ctypes.memset(block, 1, n)
    libc.free(block)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    block = libc.malloc(n)
    ctypes.memset(block, 2, n)
    print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
    """
)


def _refaults(mode: str) -> int:
    env = {**os.environ, "PYTHONPATH": os.getcwd()}
    out = subprocess.run(
        [sys.executable, "-c", _REFAULTS, mode],
        capture_output=True,
        text=True,
        check=True,
        env=env,
    )
    return int(out.stdout.strip())


@pytest.mark.skipif(not GLIBC, reason="mallopt is glibc's")
def test_a_freed_large_block_is_reused_without_faulting_its_pages_again():
    # glibc's default unmaps a block this large on free, and its pages fault in anew (every
    # 4 KiB page, or every huge page where the kernel backs the mapping with them)
    system, reuse = _refaults("system"), _refaults("reuse")
    assert system >= (64 << 20) // (2 << 20)
    assert 10 * reuse < system


@pytest.mark.parametrize("bad", [0, -1, 1 << 31, 2.5, "64", True])
def test_a_threshold_out_of_range_is_refused(bad):
    with pytest.raises(ValueError, match="threshold"):
        allocator.reuse_freed_memory(bad)


def test_the_environment_turns_the_setting_off(monkeypatch):
    calls = []
    monkeypatch.setattr(allocator, "reuse_freed_memory", lambda: calls.append(1) or True)
    monkeypatch.setenv(allocator.ENVIRONMENT, "0")
    assert allocator.reuse_freed_memory_unless_disabled() is False
    monkeypatch.setenv(allocator.ENVIRONMENT, "1")
    assert allocator.reuse_freed_memory_unless_disabled() is True
    monkeypatch.delenv(allocator.ENVIRONMENT)
    assert allocator.reuse_freed_memory_unless_disabled() is True
    assert len(calls) == 2


@pytest.mark.parametrize("disabled", [False, True])
def test_the_hopnav_command_sets_the_allocator_first(disabled):
    script = textwrap.dedent(
        """
        import sys
        import planner.allocator as a
        calls = []
        a.reuse_freed_memory = lambda: calls.append(1) or True
        from hopnav.cli import entry
        sys.argv = ["hopnav", "--version"]
        try:
            entry()
        except SystemExit:
            pass
        print("calls", len(calls))
        """
    )
    env = {**os.environ, "PYTHONPATH": os.getcwd()}
    env.pop(allocator.ENVIRONMENT, None)
    if disabled:
        env[allocator.ENVIRONMENT] = "0"
    out = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, check=True, env=env
    )
    assert out.stdout.strip().splitlines()[-1] == f"calls {0 if disabled else 1}"
