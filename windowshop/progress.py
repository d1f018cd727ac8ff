"""Progress bars for a person at a terminal, plain lines for a log: every bar goes through `bar()`.

At a terminal a tqdm bar redraws itself in place with `\\r`; written to a pipe or a file (a
service, CI, `> log.txt`) that is thousands of updates on one line. There `bar()` returns a
`LineProgress` instead: one plain line every `LINE_SECONDS` and one when it closes.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Iterable, Iterator
from typing import IO, Any

from tqdm import tqdm

LINE_SECONDS = 5.0  # seconds between the lines of a bar written to a log


def is_terminal(stream: IO) -> bool:
    """Whether `stream` is an interactive terminal (False for pipes, files and closed streams)."""
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):
        return False


class LineProgress:
    """The plain twin of a tqdm bar (the part of its interface windowshop uses): `update`,
    `set_postfix`, `close`, iteration and `with`, printing `desc: n/total unit (p%) t s, postfix`
    at most once every `interval` seconds, the first update and the close always."""

    def __init__(self, iterable: Iterable | None = None, total: int | None = None, desc: str = "",
                 unit: str = "it", initial: int = 0, file: IO | None = None,
                 interval: float = LINE_SECONDS, clock=time.monotonic):
        self.iterable, self.desc, self.unit, self.n = iterable, desc, unit, initial
        if total is None and iterable is not None and hasattr(iterable, "__len__"):
            total = len(iterable)
        self.total, self.file, self.interval, self.clock = total, file, interval, clock
        self.postfix: dict[str, Any] = {}
        self.start = clock()
        self._printed_at: float | None = None
        self._printed_n: int | None = None
        self._closed = False

    def line(self) -> str:
        """The current state as one line (no newline)."""
        count = f"{self.n}/{self.total}" if self.total else f"{self.n}"
        percent = f" ({100.0 * self.n / self.total:.0f}%)" if self.total else ""
        post = ", ".join(f"{k}={v}" for k, v in self.postfix.items())
        head = f"{self.desc}: " if self.desc else ""
        unit = f" {self.unit}" if self.unit else ""
        return (f"{head}{count}{unit}{percent} {self.clock() - self.start:.1f} s"
                + (f", {post}" if post else ""))

    def _print(self) -> None:
        print(self.line(), file=self.file or sys.stderr, flush=True)
        self._printed_at, self._printed_n = self.clock(), self.n

    def update(self, n: int = 1) -> None:
        self.n += n
        if self._printed_at is None or self.clock() - self._printed_at >= self.interval:
            self._print()

    def set_postfix(self, refresh: bool = True, **values: Any) -> None:
        self.postfix = values

    def close(self) -> None:
        if not self._closed and self._printed_n != self.n:
            self._print()
        self._closed = True

    def __iter__(self) -> Iterator:
        try:
            for item in self.iterable:
                yield item
                self.update(1)
        finally:
            self.close()

    def __enter__(self) -> LineProgress:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def bar(iterable: Iterable | None = None, *, total: int | None = None, desc: str = "",
        unit: str = "it", initial: int = 0, show: bool = True, file: IO | None = None,
        leave: bool = True) -> tqdm | LineProgress:
    """A progress bar on `file` (default stderr): tqdm at a terminal, `LineProgress` elsewhere,
    and a silent tqdm when `show` is False."""
    file = file or sys.stderr
    if show and not is_terminal(file):
        return LineProgress(iterable, total=total, desc=desc, unit=unit, initial=initial, file=file)
    return tqdm(iterable, total=total, desc=desc or None, unit=unit, initial=initial, file=file,
                disable=not show, leave=leave, dynamic_ncols=True)
