"""The frame timer's named phases: sums per name, CPU apart from wall time, errors pass through."""

import time

import pytest

from multigpu.rank.timer import Timer


def test_phases_add_up_by_name_and_span_the_frame():
    t = Timer()
    with t.phase("exchange"):
        time.sleep(0.01)
    with t.phase("sync"):
        pass
    with t.phase("exchange"):
        time.sleep(0.01)
    assert t.ms("exchange") >= 20.0
    assert t.ms("exchange", "sync") == t.ms("exchange") + t.ms("sync")
    assert t.cpu_ms("exchange") < t.ms("exchange")  # a sleeping phase spends little CPU
    assert t.total_ms >= t.ms("exchange", "sync")
    assert t.ms("render") == 0.0 and t.cpu_ms("render") == 0.0


def test_a_busy_phase_counts_cpu_and_an_error_still_closes_it():
    t = Timer()
    with pytest.raises(ZeroDivisionError):
        with t.phase("balance"):
            end = time.process_time() + 0.02
            while time.process_time() < end:
                pass
            1 / 0
    assert t.cpu_ms("balance") >= 20.0
    assert t.total_ms >= t.ms("balance") > 0.0


def test_waiting_is_the_wall_time_the_thread_did_not_run():
    t = Timer()
    with t.phase("sync"):
        time.sleep(0.02)
    with t.phase("render"):
        end = time.thread_time() + 0.02
        while time.thread_time() < end:
            pass
    assert t.waited_ms("sync") >= 19.0 and t.waited_ms("sync") <= t.ms("sync")
    assert t.waited_ms("render") < t.ms("render") - 15.0  # it ran: most of its wall time is its own
    assert t.waited_ms("sync", "render") == pytest.approx(t.waited_ms("sync") + t.waited_ms("render"))
