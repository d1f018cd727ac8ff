"""Pick the torch device once (only the CLI and the service call pick_device), what the CPU
offers the code (cpu_profile), and the CPU thread count that runs fastest as training or
rendering goes (ThreadTuner)."""

from __future__ import annotations

import collections
import os
import platform
from pathlib import Path

import torch


def pick_device(name: str | None = None) -> torch.device:
    """`name` ('cpu', 'cuda', 'cuda:1') wins; otherwise CUDA when present, else the CPU."""
    if name:
        return torch.device(name)
    return torch.device("cuda" if torch.cuda.is_available() else "cpu")


VECTOR_FLAGS = ("avx2", "fma", "avx512f", "avx512_bf16", "amx_bf16", "avx512_vnni")


def cpu_profile() -> dict:
    """What the CPU is and what of it the code uses: its model and vector flags (Linux's
    /proc/cpuinfo), PyTorch's kernels' instruction set (ATEN_CPU_CAPABILITY lowers it), whether
    oneDNN runs bfloat16 (ONEDNN_MAX_CPU_ISA=AVX2 turns it off, and with it the fast model's
    bf16 MLP) and the target the fused kernels are built for."""
    from windowshop.field.kernels import MARCH

    info = {}
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            key, _, value = line.partition(":")
            info.setdefault(key.strip(), value.strip())
    except OSError:
        pass
    flags = set(info.get("flags", "").split())
    return {"model": info.get("model name") or platform.processor() or platform.machine(),
            "cores": os.cpu_count(), "flags": [f for f in VECTOR_FLAGS if f in flags],
            "torch_capability": torch.backends.cpu.get_cpu_capability(),
            "bf16": bool(torch.ops.mkldnn._is_mkldnn_bf16_supported()), "kernels_march": MARCH,
            "profile": os.environ.get("WINDOWSHOP_CPU_PROFILE", "host")}


class ThreadTuner:
    """Keeps the CPU thread count that makes steps fastest, measured while training or rendering.

    OpenMP's threads split each kernel evenly and then wait for the slowest, spinning. When another
    process holds one of the cores, the thread sharing it finishes last and the spinning ones take
    its time slices: on the 2-core machine a fast-model step went from 29 ms to 103 ms, while one
    thread alone took 38 ms. So the tuner runs a trial, alternating all threads and half of them
    step by step (so that a burst of other work hurts both alike), keeps the faster count for
    `keep` times as long as the trial took, and tries again. Half the threads must be `margin`
    faster to be chosen. A trial is `trial_steps` steps of each or `trial_seconds` of each,
    whichever ends first, so slow steps (the NeRF's take seconds) are tried one at a time. On a
    quiet machine that costs about one percent; on a shared one it wins back a factor of two or
    more. Does nothing on CUDA or with a single thread; the first `warmup` steps (allocations,
    compilation) are not timed.
    """

    def __init__(self, device: torch.device, trial_steps: int = 8, trial_seconds: float = 0.25,
                 keep: float = 30.0, warmup: int = 2, margin: float = 0.1):
        self.full = torch.get_num_threads()
        self.counts = (self.full, max(1, self.full // 2))
        self.enabled = torch.device(device).type == "cpu" and self.full > 1
        self.trial_steps, self.trial_seconds, self.keep = trial_steps, trial_seconds, keep
        self.warmup, self.margin = warmup, margin
        self.times: dict[int, list[float]] = {}  # step seconds of the current trial, per count
        self.trying = True  # in a trial, or keeping the chosen count
        self.chosen, self.kept, self.budget = self.full, 0.0, 0.0
        self.used: collections.Counter[int] = collections.Counter()  # steps taken at each count

    def before_step(self) -> None:
        """Set the thread count for the coming step."""
        if not self.enabled:
            return
        count = self.chosen
        if self.trying and self.used.total() >= self.warmup:
            count = self.counts[sum(map(len, self.times.values())) % len(self.counts)]
        if count != torch.get_num_threads():
            torch.set_num_threads(count)

    def after_step(self, seconds: float) -> None:
        """Record how long the step took."""
        count = torch.get_num_threads()
        self.used[count] += 1
        if not self.enabled or self.used.total() <= self.warmup:
            return
        if not self.trying:
            self.kept += seconds
            if self.kept >= self.budget:
                self.trying, self.times = True, {}
            return
        self.times.setdefault(count, []).append(seconds)
        trials = [self.times.get(n, []) for n in self.counts]
        if all(len(t) >= self.trial_steps or (t and sum(t) >= self.trial_seconds) for t in trials):
            self.trying, self.chosen, self.kept = False, self.best(), 0.0
            self.budget = self.keep * sum(map(sum, trials))

    def best(self) -> int:
        """All threads, unless half of them had a median step time `margin` shorter in the trial."""
        medians = [sorted(t)[len(t) // 2] for t in (self.times.get(n) for n in self.counts) if t]
        if len(medians) < 2 or medians[1] >= (1 - self.margin) * medians[0]:
            return self.full
        return self.counts[1]

    def close(self) -> None:
        """Give the process its full thread count back."""
        if self.enabled:
            torch.set_num_threads(self.full)
