"""The exception types the CLI turns into one line on stderr and an exit status (never a traceback).

CharctlError   bad input, bad config, wrong checkpoint, an OS error on a named path  -> exit 2
Diverged       training produced a non-finite loss or parameter (the last finite      -> exit 3
               checkpoint is kept)
Interrupted    Ctrl-C (SIGINT) or SIGTERM stopped a run after its checkpoint was       -> exit 130 / 143
               written ("interrupted at ...; continue with --resume RUN")
"""

from __future__ import annotations

import signal


class CharctlError(Exception):
    """A user-facing error: bad input, bad config, wrong checkpoint. The message is one line."""

    exit_code: int = 2


class Diverged(CharctlError):
    """Training diverged (non-finite loss, statistic or parameter); see charctl.guard."""

    exit_code = 3


class Interrupted(CharctlError):
    """A run stopped by a signal after writing its checkpoint.

    `signum` is the first signal received (SIGINT -> exit 130, SIGTERM -> exit 143, the shell's
    128 + signal convention); the message says where it stopped and how to continue, e.g.
    "interrupted at iteration 12: checkpoint written; continue with --resume outputs/cgail/...".
    """

    def __init__(self, message: str = "interrupted", signum: int | None = None) -> None:
        super().__init__(message)
        self.signum = int(signum) if signum is not None else int(signal.SIGINT)
        self.exit_code = 128 + self.signum


def exit_code_for_signal(signum: int | None) -> int:
    return 128 + int(signum if signum is not None else signal.SIGINT)
