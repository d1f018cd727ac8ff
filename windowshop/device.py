"""Pick the torch device once; only the CLI and the service call this."""

from __future__ import annotations

import torch


def pick_device(name: str | None = None) -> torch.device:
    """`name` ('cpu', 'cuda', 'cuda:1') wins; otherwise CUDA when present, else the CPU."""
    if name:
        return torch.device(name)
    return torch.device("cuda" if torch.cuda.is_available() else "cpu")


class ThreadTuner:
    """Keeps the CPU thread count that makes steps fastest, measured while training.

    OpenMP's threads split each kernel evenly and then wait for the slowest, spinning. When another
    process holds one of the cores, the thread sharing it finishes last and the spinning ones take
    its time slices: on the 2-core machine a fast-model step went from 29 ms to 103 ms, while one
    thread alone took 38 ms. So every `period` steps the tuner times `trial` steps with all threads
    and `trial` with half of them, and keeps the faster count until the next trial. On a quiet
    machine that costs about one percent (8 of 200 steps a third slower); on a shared one it can win back a factor of two or more.
    Does nothing on CUDA or with a single thread.
    """

    def __init__(self, device: torch.device, period: int = 200, trial: int = 8):
        self.full = torch.get_num_threads()
        self.counts = (self.full, max(1, self.full // 2))
        self.enabled = torch.device(device).type == "cpu" and self.full > 1
        self.period, self.trial = period, trial
        self.times: dict[int, list[float]] = {}
        self.step = 0

    def _trying(self) -> int | None:
        """The thread count on trial at the current step, or None outside the trials."""
        phase = self.step % self.period
        return self.counts[phase // self.trial] if phase < 2 * self.trial else None

    def before_step(self) -> None:
        """Set the thread count for the coming step."""
        count = self._trying() or self.best()
        if self.enabled and count != torch.get_num_threads():
            torch.set_num_threads(count)

    def after_step(self, seconds: float) -> None:
        """Record how long the step took."""
        if self.enabled and (count := self._trying()) is not None:
            self.times[count] = (self.times.get(count, []) + [seconds])[-self.trial:]
        self.step += 1

    def best(self) -> int:
        """The thread count whose last trial steps had the smaller median time."""
        medians = {n: sorted(t)[len(t) // 2] for n, t in self.times.items()}
        return min(medians, key=medians.get) if medians else self.full

    def close(self) -> None:
        """Give the process its full thread count back."""
        if self.enabled:
            torch.set_num_threads(self.full)
