"""Where a bench row ran: the commit and the machine, printed beside every figure; and the
whole result printed and kept."""

from __future__ import annotations

import os
import platform
import json
import subprocess
import time
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[1]


def commit() -> str:
    """The short hash of the checked-out commit ("unknown" outside a git checkout)."""
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True,
                              text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def machine() -> dict:
    """Where and when the row ran: commit, CPU, threads and the load at the start."""
    from windowshop.device import cpu_profile

    return {"commit": commit(), "platform": platform.platform(), "cpu": cpu_profile(),
            "cpus": os.cpu_count(),
            "torch": torch.__version__, "torch_threads": torch.get_num_threads(),
            "load_average": os.getloadavg(), "time": time.strftime("%Y-%m-%d %H:%M:%S")}


def emit(results: dict, out: str | None) -> None:
    """Print `results` as indented JSON, and write it to `out` too when given."""
    text = json.dumps(results, indent=2)
    print(text)
    if out:
        Path(out).write_text(text + "\n")
