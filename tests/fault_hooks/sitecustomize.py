"""Fault injection for the test suite's charctl subprocesses (tests/test_faults.py, test_ray_launcher.py).

Python imports `sitecustomize` at start-up from sys.path, so a subprocess started with this folder on
PYTHONPATH (`conftest.cli_env` adds it whenever a CHARCTL_FAULT_* variable is given) gets these faults;
production code has no test hooks. They replace `charctl.checkpoints._save_payload`, which serialises a
checkpoint into its temp file:

  CHARCTL_FAULT_CHECKPOINT_DELAY=S   sleep S seconds in the middle of every checkpoint write (the temp
                                     file is half written), so a SIGKILL can land inside it
  CHARCTL_FAULT_CHECKPOINT_ENOSPC=N  checkpoint writes after the first N fail with ENOSPC (disk full)
"""

from __future__ import annotations

import errno
import io
import os
import time

DELAY_ENV = "CHARCTL_FAULT_CHECKPOINT_DELAY"
ENOSPC_ENV = "CHARCTL_FAULT_CHECKPOINT_ENOSPC"


def _install() -> None:
    import charctl.checkpoints

    written = [0]  # checkpoints written so far in this process

    def save_with_faults(fh, payload: dict) -> None:
        """A write that pauses with the temp file half written, or fails with ENOSPC after half of it."""
        import torch

        buf = io.BytesIO()
        torch.save(payload, buf)
        data = buf.getvalue()
        half = len(data) // 2
        fh.write(data[:half])
        fh.flush()
        limit = os.environ.get(ENOSPC_ENV)
        if limit and written[0] >= int(limit):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), fh.name)
        delay = os.environ.get(DELAY_ENV)
        if delay:
            time.sleep(float(delay))
        fh.write(data[half:])
        written[0] += 1

    charctl.checkpoints._save_payload = save_with_faults


if os.environ.get(DELAY_ENV) or os.environ.get(ENOSPC_ENV):
    _install()
