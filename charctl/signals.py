"""Clean interruption: Ctrl-C / SIGTERM become a stop request (`StopFlag`), and checkpoint writes hold them
back (`signals_held`)."""

from __future__ import annotations

import contextlib
import signal
import sys
import threading
from collections.abc import Iterator
from typing import Any

from charctl.errors import Interrupted

# ---------------------------------------------------------------------------- interruption
_STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)
_received: list[int] = []  # signals a StopFlag turned into a stop request in this process


@contextlib.contextmanager
def signals_held() -> Iterator[None]:
    """Hold SIGINT / SIGTERM back for the duration (they are delivered when it ends). Main thread only."""
    if threading.current_thread() is not threading.main_thread() or not hasattr(signal, "pthread_sigmask"):
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, set(_STOP_SIGNALS))
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def stop_signal() -> int | None:
    """The first signal a StopFlag received in this process (None if none): a training function that
    returned normally after one was still interrupted (see charctl.commands.train)."""
    return _received[0] if _received else None


class StopFlag:
    """Turns Ctrl-C (SIGINT) / SIGTERM into `requested = True` so a training loop can finish its
    iteration, write a checkpoint and raise `stop.interrupted(...)` (exit 130 / 143):

        with StopFlag() as stop:
            for it in ...:
                ...
                if stop.requested:
                    run.save_checkpoint(...)
                    raise stop.interrupted(f"interrupted at iteration {it}: checkpoint written; "
                                           f"continue with --resume {run.dir}")

    A second signal only says that the stop is under way (the checkpoint is still written, the exit
    code is the first signal's); a third one gives up on the current iteration and raises
    `Interrupted` at once (the last checkpoint on disk is kept). Checkpoint writes hold signals
    back (`signals_held`), so no signal lands inside one.
    """

    give_up_after = 3

    def __init__(self) -> None:
        self.requested = False
        self.signum: int | None = None
        self.count = 0
        self._old: dict[int, Any] = {}

    @property
    def exit_code(self) -> int:
        return 128 + int(self.signum or signal.SIGINT)

    def interrupted(self, message: str) -> Interrupted:
        return Interrupted(message, signum=self.signum)

    def _handle(self, signum, frame) -> None:  # noqa: ARG002
        self.count += 1
        if not self.requested:
            self.requested = True
            self.signum = int(signum)
            _received.append(int(signum))
            print(
                "\nstopping: finishing this iteration and writing a checkpoint (press Ctrl-C twice more to quit "
                "without it)",
                file=sys.stderr,
                flush=True,
            )
            return
        if self.count >= self.give_up_after:
            raise Interrupted(
                "interrupted before the current iteration finished; the last checkpoint on disk is kept",
                signum=self.signum,
            )
        print("\nstill stopping (press Ctrl-C once more to quit without the checkpoint)", file=sys.stderr, flush=True)

    def __enter__(self) -> StopFlag:
        for sig in _STOP_SIGNALS:
            try:
                self._old[sig] = signal.signal(sig, self._handle)
            except ValueError:  # not the main thread
                pass
        return self

    def __exit__(self, *exc) -> None:
        if self.requested:  # the run is ending with Interrupted: later signals keep counting, same exit code
            return
        for sig, old in self._old.items():
            signal.signal(sig, old)
