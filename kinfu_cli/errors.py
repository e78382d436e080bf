"""Error classes the CLI turns into one-line messages with exit code 2.

Library code raises these with the file, topic or option and what was expected;
it never prints. Anything else escaping a command is a bug.
"""

from __future__ import annotations


class KinfuError(Exception):
    """Bad input or an impossible request; the message is shown to the user as one line."""

    exit_code = 2


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
