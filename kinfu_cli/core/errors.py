"""Error classes the CLI turns into one-line messages with exit code 2.

Library code raises these with the file, topic or parameter and what was expected; it never prints
and never names a command-line flag. An error about one argument passes `parameter=` (the Python
name); the message then reads "parameter: detail", and the command layer may show the flag instead.
Anything else escaping a command is a bug.
"""

from __future__ import annotations


class KinfuError(Exception):
    """Bad input or an impossible request; the message is shown to the user as one line."""

    exit_code = 2

    def __init__(self, message: str, *, parameter: str | None = None) -> None:
        super().__init__(f"{parameter}: {message}" if parameter else message)
        self.parameter = parameter
        self.detail = message


class RecordingError(KinfuError):
    """A recording (bag, MCAP, folder) is missing, unreadable, or lacks a needed topic/frame."""


class TransformError(KinfuError):
    """A TF lookup failed: missing link, time outside the buffered range, or a bad transform."""


class TrajectoryError(KinfuError):
    """A hand or camera trajectory is empty, too short, non-finite or not rigid."""


class VolumeError(KinfuError):
    """A volume file is missing, from another version, or a volume request is impossible."""


class ConfigError(KinfuError):
    """An option value is malformed or inconsistent with the data."""
