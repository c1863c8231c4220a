"""Ctrl-C that is never lost, and never reported as another error.

Python raises ``KeyboardInterrupt`` wherever the main thread is when SIGINT comes, and some places
lose it or change it: an at-fork hook (run while a subprocess such as ffmpeg starts) prints
"Exception ignored" and goes on, and ctypes reports one raised while it converts an argument
(PyOpenGL's, in every GL call) as ``ctypes.ArgumentError``. Ctrl-C also reaches the whole process
group, so a child (ffmpeg) can die of it, and its caller fail, before Python raises it at all.

:func:`install_interrupt_handler` makes SIGINT set a flag as well as raise; long loops call
:func:`check_interrupted`, and whatever ends a command after :func:`was_interrupted` turned true
ends it as the interrupt (exit 130 from ``shapemotion``). A SIGINT the process was started to ignore
(a job a script starts in the background) stays ignored, as Python itself leaves it.

>>> previous = install_interrupt_handler()
>>> was_interrupted()
False
>>> try:
...     signal.raise_signal(signal.SIGINT)
... except KeyboardInterrupt:
...     pass                      # a library that swallows the interrupt
>>> was_interrupted()
True
>>> _ = signal.signal(signal.SIGINT, previous)
"""

from __future__ import annotations

import signal
import threading

from stimuli.workers import check_orphaned

_INTERRUPTED = threading.Event()


def install_interrupt_handler():
    """Make Ctrl-C stick: SIGINT sets a flag as well as raising KeyboardInterrupt (the flag is cleared).

    Returns the previous handler (for ``signal.signal``), or None outside the main thread, where
    none can be installed (and the flag is left as it is). An ignored SIGINT is left ignored (the
    flag is cleared; the returned ``SIG_IGN`` restores nothing new).
    """
    if threading.current_thread() is not threading.main_thread():
        return None
    _INTERRUPTED.clear()
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        return signal.SIG_IGN

    def handler(signum, frame):
        _INTERRUPTED.set()
        raise KeyboardInterrupt

    return signal.signal(signal.SIGINT, handler)


def was_interrupted() -> bool:
    """Whether SIGINT came since :func:`install_interrupt_handler`, even if its exception was lost."""
    return _INTERRUPTED.is_set()


def check_interrupted() -> None:
    """Raise the interrupt, or the parent's death in a worker, that was swallowed."""
    if _INTERRUPTED.is_set():
        raise KeyboardInterrupt
    check_orphaned()
