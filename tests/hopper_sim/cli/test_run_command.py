"""`hopnav run` end to end on a short horizon: JSON, recording and figure of a real run."""

import json
import os
import signal
import sys
import time

import pytest

from hopper_sim.cli import main
from hopper_sim.viz.recording_reader import summarize_recording

LISTED = (
    "world/grid",
    "run_{k}/hop/com_arc",
    "run_{k}/hop/foot",
    "run_{k}/hop/leg",
    "run_{k}/hop/target",
    "run_{k}/hops",
    "run_{k}/gp/mean",
    "run_{k}/gp/image/std_y",
    "run_{k}/route",
    "run_{k}/plots/p_worst",
    "run_{k}/plots/total_reward",
    "run_{k}/plots/phase",
    "run_{k}/outcome",
)


def test_run_writes_consistent_recording_and_figure(tmp_path, capsys):
    rrd, png = tmp_path / "out.rrd", tmp_path / "out.png"
    args = ["run", "--scenario", "c", "--runs", "2", "--max-steps", "8", "--seed", "3"]
    assert main([*args, "--rrd", str(rrd), "--png", str(png), "--json"]) == 0
    runs = json.loads(capsys.readouterr().out)
    assert len(runs) == 2
    for r in runs:
        assert r["outcome"] in ("success", "violation", "timeout")
        assert 1 <= r["steps"] <= 8 and r["rrd"] == str(rrd) and r["png"] == str(png)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    summary = summarize_recording(rrd)
    for k, r in enumerate(runs):
        for name in LISTED:  # runs are numbered from 1
            assert name.format(k=k + 1) in summary["entities"], name.format(k=k + 1)
        rec = summary["runs"][k]
        assert rec["run"] == k + 1
        fell = r["reason"].startswith("hop failed")
        assert rec["hops"] == r["steps"] - fell
        assert rec["outcome"] == r["outcome"] and rec["steps"] == r["steps"]
        assert abs(rec["reward"] - r["reward"]) < 1e-9
    assert {"hop", "sim_time"} <= set(summary["timelines"])
    # hopnav replay prints the summary headlessly
    assert main(["replay", str(rrd)]) == 0
    out = capsys.readouterr().out
    assert "run_1/hop/com_arc" in out and "run 2:" in out and summary["blueprint"]


def test_run_rejects_bad_scenario(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text("[world]\nsize = [5, 5]\n")
    assert main(["run", "--scenario", str(bad), "--no-rrd", "--no-png"]) == 2
    assert "bad.toml" in capsys.readouterr().err


def test_a_product_beyond_the_limits_is_refused_before_the_first_hop(tmp_path, capsys, monkeypatch):
    import planner.imdp.product as product

    monkeypatch.setattr(product, "MAX_PRODUCT_ENTRIES", 1000)  # case (a): 226 x 3 states
    rrd = tmp_path / "a.rrd"
    code = main(["run", "--scenario", "a", "--rrd", str(rrd), "--no-png", "--quiet"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1, err
    assert "scenario a: the product of 226 model states and 3 automaton states" in err
    assert "more than the limit of 1000" in err and not rrd.exists()


@pytest.mark.parametrize("kind", [signal.SIGINT, signal.SIGTERM])
def test_an_interrupt_during_an_event_lands_after_every_observer_has_it(kind):
    from hopper_sim.cli.run import _WholeEvents
    from hopper_sim.navigation.events import Observer, Observers

    got = []

    class Signals(Observer):
        def on_run_end(self, event):
            got.append(("first", event))
            os.kill(os.getpid(), kind)  # the handler runs here, mid-event
            got.append(("first, after the signal", event))

    class Later(Observer):
        def on_run_end(self, event):
            got.append(("later", event))

    whole = _WholeEvents(Observers([Signals(), Later()]))
    with whole.interrupts_between_events():
        with pytest.raises(KeyboardInterrupt):
            whole.on_run_end("end")
        assert [g[0] for g in got] == ["first", "first, after the signal", "later"]
        with pytest.raises(KeyboardInterrupt):  # between events: at once
            os.kill(os.getpid(), kind)
            time.sleep(1.0)
    assert signal.getsignal(kind) is not whole._signal  # restored


@pytest.mark.parametrize("kind", [signal.SIGINT, signal.SIGTERM])
def test_an_interrupt_inside_a_finalizer_is_not_lost(kind):
    import gc

    from hopper_sim.cli.run import _WholeEvents
    from hopper_sim.navigation.events import Observers

    class Signals:
        def __del__(self):
            os.kill(os.getpid(), kind)  # the handler runs here, inside __del__

    whole = _WholeEvents(Observers([]))
    with whole.interrupts_between_events():
        with pytest.raises(KeyboardInterrupt):
            Signals()
            gc.collect()
            time.sleep(1.0)
    assert sys.unraisablehook is not whole._dropped  # restored
