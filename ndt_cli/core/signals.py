"""Ctrl-C and SIGTERM held back while a thread or process starts.

A KeyboardInterrupt raised while a pool starts a thread or a process can leave it started but
not recorded: a worker thread that the interpreter's exit then waits for forever (a Python
thread pool records its thread after starting it), or a worker process whose start-up prints a
traceback. Where that can happen, :func:`stop_signals_held` holds the signals back and gives
them once the start is done.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator

STOP_SIGNALS = frozenset({signal.SIGINT, signal.SIGTERM})


@contextlib.contextmanager
def stop_signals_held() -> Iterator[None]:
    """Hold Ctrl-C and SIGTERM back for the block: blocked in this thread (a thread or a forked
    process started here inherits the mask: a signal to the process group waits in it until
    it unblocks or ignores them), and, in the main thread, noted by a handler of their own
    rather than raised (another thread of the process may receive them). Given again, each
    once, when the block ends (an ignored signal stays ignored)."""
    if not hasattr(signal, "pthread_sigmask"):
        yield
        return
    caught: list[int] = []
    main = threading.current_thread() is threading.main_thread()
    old_mask = signal.pthread_sigmask(signal.SIG_BLOCK, STOP_SIGNALS)
    old = {s: signal.signal(s, lambda n, _: caught.append(n)) for s in STOP_SIGNALS if main}
    try:
        yield
    finally:
        for s, handler in old.items():
            signal.signal(s, handler)
        signal.pthread_sigmask(signal.SIG_SETMASK, old_mask)
        for s in dict.fromkeys(caught):
            signal.raise_signal(s)
