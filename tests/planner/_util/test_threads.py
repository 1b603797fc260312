"""The planner's worker threads and running two pieces of work at once."""

from __future__ import annotations

import threading
import time

import pytest

from planner._util.threads import concurrently, worker


def test_concurrently_runs_the_background_on_its_worker_and_returns_both_results():
    here = threading.get_ident()
    (bg_thread, bg), (fg_thread, fg) = concurrently(
        lambda: (threading.get_ident(), "background"),
        lambda: (threading.get_ident(), "foreground"),
        "test",
    )
    assert (bg, fg) == ("background", "foreground")
    assert fg_thread == here and bg_thread != here


def test_concurrently_overlaps_the_two_pieces_of_work():
    started = threading.Event()

    def background():
        started.set()
        time.sleep(0.2)
        return "done"

    def foreground():
        # the background runs meanwhile: it has started before this returns
        assert started.wait(5.0)
        return "here"

    assert concurrently(background, foreground, "test") == ("done", "here")


def test_a_foreground_error_waits_for_the_background_and_a_background_error_is_raised():
    finished = []

    def slow():
        time.sleep(0.1)
        finished.append(True)

    def fail():
        raise ValueError("foreground")

    with pytest.raises(ValueError, match="foreground"):
        concurrently(slow, fail, "test")
    assert finished == [True]  # the background had ended when the error came out

    ran = []

    def broken():
        raise RuntimeError("background")

    with pytest.raises(RuntimeError, match="background"):
        concurrently(broken, lambda: ran.append(True), "test")
    assert ran == [True]


def test_one_worker_per_purpose():
    assert worker("test") is worker("test")
    assert worker("test") is not worker("other test")


@pytest.mark.skipif(not hasattr(__import__("os"), "fork"), reason="needs fork")
def test_a_forked_child_gets_its_own_worker():
    import multiprocessing

    parent = worker("test")
    ctx = multiprocessing.get_context("fork")
    with ctx.Pool(1) as pool:
        child_thread, same = pool.apply(_child_worker_check, (id(parent),))
    assert same is False
    assert child_thread != threading.get_ident()


def _child_worker_check(parent_id: int) -> tuple[int, bool]:
    (tid, _), _ = concurrently(lambda: (threading.get_ident(), 1), lambda: 2, "test")
    return tid, id(worker("test")) == parent_id
