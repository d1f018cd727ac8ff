"""How a failed job's exception is sorted (retried or not) and the reason the job shows."""

from __future__ import annotations

import errno

import pytest
import torch

from windowshop.errors import UserError, failure_reason, is_transient


@pytest.mark.parametrize("err, transient", [
    (MemoryError(), True),
    (torch.OutOfMemoryError("CUDA out of memory"), True),
    (TimeoutError(), True),
    (ConnectionRefusedError(), True),
    (UserError("only 2 of 12 photos could be placed"), False),
    (OSError(errno.ENOSPC, "No space left on device"), False),
    (KeyError("a bug"), False),
])
def test_only_faults_of_the_moment_are_transient(err, transient):
    assert is_transient(err) is transient


def test_the_reason_a_failed_job_shows():
    assert failure_reason(UserError("take more photos")) == "take more photos"
    assert "disk filled up" in failure_reason(OSError(errno.ENOSPC, "No space left on device"))
    assert failure_reason(torch.OutOfMemoryError("CUDA out of memory")).startswith("out of memory")
    assert failure_reason(KeyError("x")) == "internal error (KeyError: 'x')"
