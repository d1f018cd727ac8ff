"""The thread tuner keeps the thread count whose trial steps were faster."""

import pytest
import torch

from windowshop.device import ThreadTuner


@pytest.fixture
def two_threads():
    """The process at two threads (what the tuner starts from), restored afterwards."""
    before = torch.get_num_threads()
    torch.set_num_threads(2)
    yield
    torch.set_num_threads(before)


def run_steps(tuner: ThreadTuner, times: list[dict[int, float]]) -> list[int]:
    """Drive `tuner` through steps lasting times[k][threads] seconds; the thread counts used."""
    used = []
    for step_times in times:
        tuner.before_step()
        used.append(torch.get_num_threads())
        tuner.after_step(step_times[used[-1]])
    return used


def test_a_contended_cpu_gets_fewer_threads_and_the_count_comes_back(two_threads):
    tuner = ThreadTuner(torch.device("cpu"), trial_steps=2, trial_seconds=10.0, keep=1.0, warmup=1)
    busy = {2: 0.10, 1: 0.04}  # one core taken by another process: one thread wins
    # warm-up, a trial alternating two steps of each (0.28 s), one thread for 0.28 s, a new trial
    assert run_steps(tuner, [busy] * 12) == [2] + [2, 1, 2, 1] + [1] * 7
    quiet = {2: 0.03, 1: 0.05}  # the other process left
    assert run_steps(tuner, [quiet] * 8) == [2, 1, 2, 1] + [2] * 4
    tuner.close()
    assert torch.get_num_threads() == 2
    assert tuner.used == {2: 9, 1: 11}


def test_slow_steps_are_tried_one_at_a_time(two_threads):
    tuner = ThreadTuner(torch.device("cpu"), trial_steps=3, trial_seconds=1.0, keep=10.0, warmup=0)
    assert run_steps(tuner, [{2: 3.0, 1: 5.0}] * 4) == [2, 1, 2, 2]


def test_an_outlier_or_a_small_gain_does_not_take_threads_away(two_threads):
    tuner = ThreadTuner(torch.device("cpu"), trial_steps=3, trial_seconds=10.0, warmup=0)
    quiet = {2: 0.03, 1: 0.04}
    used = run_steps(tuner, [{2: 0.50, 1: 0.04}] + [quiet] * 7)  # a grid growth at the first step
    assert used == [2, 1, 2, 1, 2, 1, 2, 2]
    tuner = ThreadTuner(torch.device("cpu"), trial_steps=3, trial_seconds=10.0, warmup=0)
    assert run_steps(tuner, [{2: 0.030, 1: 0.029}] * 8)[6:] == [2, 2]  # within the margin


def test_the_tuner_leaves_cuda_and_single_threads_alone():
    assert not ThreadTuner(torch.device("cuda")).enabled
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        assert not ThreadTuner(torch.device("cpu")).enabled
    finally:
        torch.set_num_threads(before)
