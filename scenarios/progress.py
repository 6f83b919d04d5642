"""Progress lines on stderr for long runs (steps with elapsed time, and loop counters)."""

from __future__ import annotations

import sys
import time
from typing import TextIO


class Progress:
    def __init__(self, name: str, stream: TextIO | None = None, quiet: bool = False) -> None:
        self.name = name
        self.stream = stream or sys.stderr
        self.quiet = quiet
        self.t0 = time.perf_counter()

    def _write(self, text: str) -> None:
        if not self.quiet:
            print(
                f"[{self.name} {time.perf_counter() - self.t0:6.1f}s] {text}",
                file=self.stream,
                flush=True,
            )

    def step(self, text: str) -> None:
        self._write(text)

    def note(self, text: str) -> None:
        self._write(f"  {text}")

    def counter(self, label: str, done: int, total: int, every: int = 1) -> None:
        """Report loop progress every ``every`` items and at the end."""
        if done == total or done % max(every, 1) == 0:
            self._write(f"  {label}: {done}/{total}")
