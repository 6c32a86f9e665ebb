"""ArrivalPeriod: the median interval between the last arrivals, robust to a pause."""
from __future__ import annotations

import pytest

from cemnet_ros.runtime.arrival_period import WINDOW, ArrivalPeriod


def test_none_before_three_arrivals_then_the_median_interval():
    period = ArrivalPeriod()
    for t in (0.0, 0.1):
        period.arrived(t)
        assert period.seconds is None
    period.arrived(0.2)
    assert period.seconds == pytest.approx(0.1)


def test_a_pause_in_the_input_does_not_move_it_and_the_window_forgets():
    period = ArrivalPeriod()
    times = [0.05 * k for k in range(10)] + [5.0 + 0.05 * k for k in range(10)]  # a 4.5 s pause in 20 Hz input
    for t in times:
        period.arrived(t)
    assert period.seconds == pytest.approx(0.05)
    for k in range(WINDOW):
        period.arrived(10.0 + 0.2 * k)  # the sensor now at 5 Hz
    assert period.seconds == pytest.approx(0.2)
