"""Cancelling work started ahead of need (a look's maps prepared on a thread while the first
frame is read): whoever started it sets a `threading.Event`; the work checks it between
steps and between the bands of a map (:func:`check`) and stops with `Cancelled`.

The event is per thread (:func:`scope`), so effects need no extra argument and a render on
the main thread, which never cancels, pays one attribute lookup per band.
"""
from __future__ import annotations

import threading
from contextlib import contextmanager

_local = threading.local()


class Cancelled(Exception):
    """The work was cancelled by whoever started it (never reaches a user)."""


@contextmanager
def scope(event: threading.Event | None):
    """Within this block, :func:`check` on this thread raises once ``event`` is set."""
    previous = getattr(_local, "event", None)
    _local.event = event
    try:
        yield
    finally:
        _local.event = previous


def check() -> None:
    """Raise `Cancelled` when this thread's work was cancelled (see :func:`scope`)."""
    event = getattr(_local, "event", None)
    if event is not None and event.is_set():
        raise Cancelled()
