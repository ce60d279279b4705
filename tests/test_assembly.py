"""The stopwatch of a solve's parts (valve_dolfinx.solvers.assembly.Laps), on a fake clock."""

from __future__ import annotations

import time

import pytest

from valve_dolfinx.solvers.assembly import Laps


def test_each_lap_is_charged_to_its_name_once(monkeypatch):
    """Readings 0, 2, 3, 7, 8 s: "a" gets 0→2 and 7→8, "b" 2→3, and 3→7 (before a start)
    nobody."""
    clock = iter([0.0, 2.0, 3.0, 7.0, 8.0])
    monkeypatch.setattr(time, "perf_counter", lambda: next(clock))
    laps = Laps()
    laps("a")
    laps("b")
    laps.start()
    laps("a")
    assert laps.seconds == pytest.approx({"a": 3.0, "b": 1.0})
