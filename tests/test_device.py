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


def run_steps(tuner: ThreadTuner, times) -> list[int]:
    """Drive `tuner` through steps lasting times(threads, k) seconds; the thread counts used."""
    used = []
    for k in range(len(times)):
        tuner.before_step()
        used.append(torch.get_num_threads())
        tuner.after_step(times[k][used[-1]])
    return used


def test_a_contended_cpu_gets_fewer_threads_and_the_count_comes_back(two_threads):
    tuner = ThreadTuner(torch.device("cpu"), period=10, trial=2)
    used = run_steps(tuner, [{2: 0.10, 1: 0.04}] * 10)  # one core busy: one thread wins
    assert used == [2, 2, 1, 1] + [1] * 6
    used = run_steps(tuner, [{2: 0.03, 1: 0.05}] * 10)  # the other process left
    assert used == [2, 2, 1, 1] + [2] * 6
    tuner.close()
    assert torch.get_num_threads() == 2


def test_one_slow_step_in_a_trial_does_not_decide(two_threads):
    tuner = ThreadTuner(torch.device("cpu"), period=20, trial=3)
    quiet = {2: 0.03, 1: 0.04}
    used = run_steps(tuner, [quiet, {2: 0.50, 1: 0.04}] + [quiet] * 6)  # a grid growth at step 2
    assert used == [2, 2, 2, 1, 1, 1, 2, 2]


def test_the_tuner_leaves_cuda_and_single_threads_alone():
    assert not ThreadTuner(torch.device("cuda")).enabled
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        assert not ThreadTuner(torch.device("cpu")).enabled
    finally:
        torch.set_num_threads(before)
