"""The threads over_chunks hands chunks to (ecs_anim.runtime.kernels.handover): each chunk run once,
errors raised after every chunk is done, a sleeping thread woken, a second caller served."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from ecs_anim.runtime.kernels.handover import SpinningThreads, spin_while_equal


def test_spin_returns_the_new_value_or_the_old_one_when_nothing_changed():
    counters = np.array([3, 7], np.int64)
    assert spin_while_equal(counters, 1, 3, 10) == 7
    assert spin_while_equal(counters, 0, 3, 10) == 3


@pytest.mark.parametrize("spin_s", [0.0005, 1e-7])  # waiting spinning, and asleep
def test_every_chunk_runs_once_in_its_thread(spin_s):
    pool = SpinningThreads(2, spin_s)
    ran: list[tuple[int, int, str]] = []

    def record(lo: int, hi: int, tag: str) -> None:
        ran.append((lo, hi, threading.current_thread().name))
        assert tag == "rows"

    try:
        for _ in range(3):
            ran.clear()
            pool.run(record, [0, 5, 9, 12], ("rows",))
            assert sorted((lo, hi) for lo, hi, _ in ran) == [(0, 5), (5, 9), (9, 12)]
            assert len({name for *_, name in ran}) == 3
            time.sleep(0.002)  # past the spin: the workers sleep with spin_s 1e-7
    finally:
        pool.close()


def test_a_chunks_error_is_raised_after_every_chunk_is_done():
    pool = SpinningThreads(1)
    done: list[int] = []

    def slow_or_failing(lo: int, hi: int) -> None:
        if lo > 0:
            raise ValueError(f"rows {lo}..{hi}")
        time.sleep(0.01)
        done.append(lo)

    try:
        with pytest.raises(ValueError, match=r"rows 4\.\.8"):
            pool.run(slow_or_failing, [0, 4, 8], ())
        assert done == [0]
        pool.run(lambda lo, hi: done.append(lo), [0, 4, 8], ())  # the error was not kept
        assert sorted(done) == [0, 0, 4]
    finally:
        pool.close()


def test_a_call_while_another_runs_does_its_chunks_itself():
    pool = SpinningThreads(1)
    inside = threading.Event()
    release = threading.Event()
    second: list[tuple[int, int, str]] = []

    def hold(lo: int, hi: int) -> None:
        if lo == 0:
            inside.set()
            release.wait(5)

    def record(lo: int, hi: int) -> None:
        second.append((lo, hi, threading.current_thread().name))

    first = threading.Thread(target=pool.run, args=(hold, [0, 2, 4], ()))
    first.start()
    try:
        assert inside.wait(5)
        pool.run(record, [0, 2, 4], ())
        assert [(lo, hi) for lo, hi, _ in second] == [(0, 2), (2, 4)]
        assert {name for *_, name in second} == {threading.current_thread().name}
    finally:
        release.set()
        first.join()
        pool.close()
