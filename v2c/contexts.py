"""One idiom for the settings a command puts in force for the scans it loads (limits, picking, a recording's frame,
depth clean-up): a `contextvars.ContextVar` set for the length of a ``with`` block and restored after it."""

from __future__ import annotations

import contextlib
import contextvars
from collections.abc import Iterator
from typing import TypeVar

T = TypeVar("T")


@contextlib.contextmanager
def scoped(var: contextvars.ContextVar[T], value: T) -> Iterator[T]:
    """Set ``var`` to ``value`` inside the block (yielding ``value``) and restore what it held before, also when
    the block raises."""
    token = var.set(value)
    try:
        yield value
    finally:
        var.reset(token)
