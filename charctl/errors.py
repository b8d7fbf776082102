"""The one exception type the CLI turns into a one-line error message (exit code 2)."""


class CharctlError(Exception):
    """A user-facing error: bad input, bad config, wrong checkpoint. The message is one line."""
