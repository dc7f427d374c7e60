"""Ctrl-C that stops a run between episodes instead of wherever it lands.

Python delivers SIGINT as a ``KeyboardInterrupt`` in whatever code runs at that
moment; during a reset that is often SAPIEN's ``Scene.__del__``, where the
exception is printed and swallowed and the run goes on. :class:`StopRequest`
replaces the handler while a run is going: the first Ctrl-C only sets a flag the
runner checks between episodes (and between the stages of one), a second one
raises ``KeyboardInterrupt`` and a third ends the process at once
(``os._exit``), for the case where the second was swallowed too.
"""

from __future__ import annotations

import os
import signal
import sys
import threading

__all__ = ["StopRequest", "INTERRUPTED_EXIT_CODE"]

# The shell's convention for a process ended by SIGINT (128 + 2).
INTERRUPTED_EXIT_CODE = 130


class StopRequest:
    """A context manager; ``bool(stop)`` is True once Ctrl-C was pressed (or :meth:`set` called).

    Outside the main thread signal handlers cannot be installed: the flag then only
    follows :meth:`set`.
    """

    def __init__(self, message: str = "stopping after the episodes in progress (Ctrl-C again to abort now)") -> None:
        self.message = message
        self.presses = 0
        self._previous = None
        self._installed = False

    def set(self) -> None:
        self.presses = max(self.presses, 1)

    def __bool__(self) -> bool:
        return self.presses > 0

    def _handle(self, signum, frame) -> None:
        self.presses += 1
        if self.presses == 1:
            print(f"\n{self.message}", file=sys.stderr, flush=True)
        elif self.presses == 2:
            raise KeyboardInterrupt
        else:
            os._exit(INTERRUPTED_EXIT_CODE)

    def __enter__(self) -> "StopRequest":
        if threading.current_thread() is threading.main_thread():
            self._previous = signal.signal(signal.SIGINT, self._handle)
            self._installed = True
        return self

    def __exit__(self, *exc_info: object) -> None:
        if self._installed:
            signal.signal(signal.SIGINT, self._previous)
            self._installed = False
