"""Ctrl-C during a long call stops the library at its next safe point and raises KeyboardInterrupt."""

import signal
import threading
import time

import pytest

import specmux


def test_ctrl_c_stops_a_long_reconstruction_and_the_session_goes_on():
    # GAP-TV for 100 000 iterations at 256²: over ten minutes of work, stopped after half a second.
    exp = specmux.Experiment.from_dict(
        {
            "scene": {"size": [256, 256]},
            "reconstruct": {"gap": {"method": "gap-tv", "iterations": 100000}},
        },
        "ctrl-c.toml",
    )
    timer = threading.Timer(0.5, signal.raise_signal, args=(signal.SIGINT,))
    timer.start()
    started = time.monotonic()
    with pytest.raises(KeyboardInterrupt):
        specmux.run(exp)
    timer.join()
    # The stop came from the signal, not from the end of the work (100 000 iterations would
    # take far longer than this generous bound).
    assert time.monotonic() - started < 120
    # The stop request was cleared: the next call runs to its end.
    small = specmux.Experiment.prototype(size=32)
    assert specmux.run(small)["report"]["results"]
