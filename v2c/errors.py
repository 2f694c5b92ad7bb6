"""The error type v2c raises for bad input or an unusable environment.

A `V2cError` message is meant for the user as it stands: one line naming the file (or option), the value and
what was expected. The `v2c` command prints it as ``error: <message>`` with exit status 1 and no traceback;
any other exception reaching the command line is a bug of v2c and is reported as such.
"""

from __future__ import annotations


class V2cError(Exception):
    """Bad input or an unusable environment, explained in one line (file, value, what was expected)."""


class OutputError(V2cError, OSError):
    """An output could not be written (a folder that is not writable, a name taken by another file, ...)."""


class ScanError(V2cError, ValueError):
    """A scan folder that cannot be used. The message names the file and the problem."""
