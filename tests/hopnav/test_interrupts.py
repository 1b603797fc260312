"""Ctrl-C deferred where it cannot land safely: numba, torch, imports, a thread pool
starting (hopnav.interrupts)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from hopnav import interrupts

ROOT = Path(__file__).resolve().parents[2]


def _frame_in(filename: str):
    """A live frame of code compiled as if from ``filename``."""
    space: dict = {}
    exec(compile("import sys\ndef here():\n    return sys._getframe()\n", filename, "exec"), space)
    return space["here"]()


def test_frames_of_numba_llvmlite_torch_imports_and_thread_pools_are_unsafe():
    for name in ("numba", "llvmlite", "torch"):
        path = os.sep.join(["", "site-packages", name, "core", "x.py"])
        assert interrupts.in_unsafe_code(_frame_in(path))
    for path in ("<frozen importlib._bootstrap>", "<frozen importlib._bootstrap_external>"):
        assert interrupts.in_unsafe_code(_frame_in(path))
    pool = os.sep.join(["", "lib", "python3.11", "concurrent", "futures", "thread.py"])
    assert interrupts.in_unsafe_code(_frame_in(pool))
    waiting = os.sep.join(["", "lib", "python3.11", "concurrent", "futures", "_base.py"])
    assert not interrupts.in_unsafe_code(_frame_in(waiting))  # waiting on a result is safe
    assert not interrupts.in_unsafe_code(_frame_in(os.sep.join(["", "work", "planner", "x.py"])))
    assert not interrupts.in_unsafe_code(sys._getframe())
    assert not interrupts.in_unsafe_code(None)


def test_the_code_of_a_module_being_imported_is_unsafe(tmp_path, monkeypatch):
    """A module's own code runs below importlib's frames while it is imported (an
    extension's initialisation may call it), and not once it is."""
    (tmp_path / "hopnav_probe_module.py").write_text(
        "import sys\nfrom hopnav.interrupts import in_unsafe_code\n"
        "DURING = in_unsafe_code(sys._getframe())\n"
        "def after():\n    return in_unsafe_code(sys._getframe())\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    import hopnav_probe_module as probe

    try:
        assert probe.DURING is True
        assert probe.after() is False
    finally:
        sys.modules.pop("hopnav_probe_module", None)


def test_an_interrupt_inside_the_compiler_is_delivered_again_later(monkeypatch):
    sent = []
    monkeypatch.setattr(interrupts._thread, "interrupt_main", sent.append)
    inside = _frame_in(os.sep.join(["", "site-packages", "llvmlite", "binding", "ffi.py"]))
    assert interrupts.interrupt_here(signal.SIGINT, inside) is False
    deadline = time.monotonic() + 5.0
    while not sent and time.monotonic() < deadline:
        time.sleep(0.005)
    assert sent == [signal.SIGINT]
    assert interrupts.interrupt_here(signal.SIGINT, sys._getframe()) is True


_SCRIPT = textwrap.dedent(
    """
    import os, sys, time
    from hopnav.cli import _signals_as_interrupt
    space = {}
    # a stand-in for numba's compiler: a second of Python code from a numba path
    src = "import time\\ndef compile_kernel(ready):\\n    ready()\\n    t = time.monotonic()\\n"
    src += "    while time.monotonic() - t < 1.0:\\n        pass\\n    return 'compiled'\\n"
    fake = os.sep.join(["", "site-packages", "numba", "core", "compiler.py"])
    exec(compile(src, fake, "exec"), space)
    done = []
    with _signals_as_interrupt():
        try:
            done.append(space["compile_kernel"](lambda: print("ready", flush=True)))
            t = time.monotonic()
            while time.monotonic() - t < 10.0:
                pass
            print("no interrupt")
        except KeyboardInterrupt:
            print("interrupted after", done)
    """
)


@pytest.mark.parametrize("kind", [signal.SIGINT, signal.SIGTERM])
def test_the_command_takes_an_interrupt_once_the_compiler_has_returned(kind):
    proc = subprocess.Popen(
        [sys.executable, "-c", _SCRIPT],
        stdout=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    assert proc.stdout.readline().strip() == "ready"
    time.sleep(0.2)  # inside the stand-in compiler
    proc.send_signal(kind)
    out, _ = proc.communicate(timeout=60)
    assert proc.returncode == 0
    assert out.strip() == "interrupted after ['compiled']"


def _interrupted(setup: str, step: str, timeout: float) -> str:
    """Run ``step`` under the commands' handlers in a fresh process (after ``setup``, which
    arranges the interrupt) and return where the interrupt came: "during" or "after"
    ``step``. The process must exit with status 0 within ``timeout`` seconds."""
    body = textwrap.indent(textwrap.dedent(step).strip(), " " * 8)
    code = textwrap.dedent(setup) + textwrap.dedent(
        """
        from hopnav.cli import _signals_as_interrupt
        where = "during"
        with _signals_as_interrupt():
            try:
        {body}
                where = "after"
                t = time.monotonic()
                while time.monotonic() - t < 10.0:
                    pass
                print("no interrupt")
            except KeyboardInterrupt:
                print(where, flush=True)
        """
    ).replace("{body}", body)
    proc = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        timeout=timeout,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    return proc.stdout.strip()


_START_THEN_INTERRUPT = """
import os, signal, threading, time
from concurrent.futures import ThreadPoolExecutor
start = threading.Thread.start

def start_then_interrupt(self):
    # the window of the hang: the pool's thread runs, not yet registered for shutdown
    start(self)
    os.kill(os.getpid(), signal.SIGINT)
    t = time.monotonic()
    while time.monotonic() - t < 0.5:
        pass

threading.Thread.start = start_then_interrupt
pool = ThreadPoolExecutor(1)
"""


def test_an_interrupt_while_a_thread_pool_starts_its_thread_waits_and_the_process_exits():
    """Raised inside ``submit`` after the pool's thread started, an interrupt left the
    thread unregistered, and the interpreter waited for it at exit for ever (a sweep
    interrupted in its first seconds hung so in CI). Deferred, it comes after ``submit``,
    and the process exits."""
    assert _interrupted(_START_THEN_INTERRUPT, "pool.submit(time.sleep, 0.01)", 60) == "after"


_SOON = """
import os, signal, threading, time
threading.Timer(0.05, os.kill, (os.getpid(), signal.SIGINT)).start()
"""


def test_an_interrupt_during_the_import_of_torch_comes_after_it():
    """Raised inside torch's import, an interrupt passes through its C++ (pybind11): the
    process aborted, or Python, told the interrupt was unhandled, killed itself with SIGINT
    at exit although the command had caught it (status -2)."""
    assert _interrupted(_SOON, "import torch", 120) == "after"
