"""The one terminal view of a run: children's lines with role prefixes, plus a status line.

On a terminal the status line stays at the bottom (rewritten in place); elsewhere (CI, a pipe) it
is printed as an ordinary line every ``plain_period_s``, so logs stay readable.
"""

from __future__ import annotations

import sys
import threading
import time
from typing import TextIO


class Console:
    def __init__(self, stream: TextIO | None = None, plain_period_s: float = 10.0) -> None:
        self.stream = stream or sys.stdout
        self.tty = self.stream.isatty()
        self.plain_period_s = plain_period_s
        self._lock = threading.Lock()
        self._status = ""
        self._last_plain = 0.0

    def line(self, text: str) -> None:
        """A child's output line (or any message): above the status line."""
        with self._lock:
            if self.tty and self._status:
                self.stream.write("\r\033[K" + text + "\n" + self._status)
            else:
                self.stream.write(text + "\n")
            self.stream.flush()

    def status(self, text: str) -> None:
        with self._lock:
            if self.tty:
                self._status = text
                self.stream.write("\r\033[K" + text)
                self.stream.flush()
                return
            now = time.monotonic()
            if now - self._last_plain >= self.plain_period_s:
                self._last_plain = now
                self.stream.write(text + "\n")
                self.stream.flush()

    def block(self, text: str) -> None:
        """A multi-line block (a table) that replaces the previous one on a terminal."""
        with self._lock:
            if self.tty:
                self.stream.write("\033[H\033[J" + text + "\n")
            else:
                self.stream.write(text + "\n")
            self.stream.flush()

    def close(self) -> None:
        with self._lock:
            if self.tty and self._status:
                self.stream.write("\n")
                self.stream.flush()
            self._status = ""
