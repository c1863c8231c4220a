"""Process pools whose workers die with the process that started them.

A ``ProcessPoolExecutor`` worker blocks on its task queue, and it holds both ends of that queue's
pipe itself, so it never sees the pipe close: when the main process is killed (``kill -9``, the
OOM killer, SIGTERM or a closed terminal's SIGHUP) its workers — ~740 MB each for a render — live on,
reparented to PID 1, and with them multiprocessing's resource tracker, which exits only once every
process holding its pipe (the workers are given it at spawn) has gone.

:func:`process_pool` makes spawned workers that notice their parent's death in two ways:

- a parent-death signal (Linux ``prctl(PR_SET_PDEATHSIG)``), delivered by the kernel the moment
  the parent dies, and
- a watchdog thread that polls ``os.getppid()`` (a reparented process sees another parent), for
  systems without ``prctl``.

Either way the worker gets :data:`PARENT_DIED` (SIGUSR1), which raises ``SystemExit`` in its main
thread, so the task it was running unwinds (``finally`` blocks and ``except BaseException``
clean-ups run: a clip being encoded deletes its temporary folder; :func:`check_orphaned` raises it
again where a library swallowed it) and the worker leaves without starting another task; should
the task not unwind in time (a slow frame on a loaded machine, a hung call), the watchdog runs the
clean-ups registered with :func:`at_forced_exit` and ends the process after :data:`GRACE_S` seconds.
With the workers gone the resource tracker reads EOF and exits.

>>> with process_pool(1) as pool:
...     pool.submit(abs, -3).result()
3
"""

from __future__ import annotations

import ctypes
import os
import signal
import sys
import threading
import time
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context

POLL_S = 0.25   # how often the watchdog looks at the parent: a dead parent is noticed within this
GRACE_S = 5.0   # time a task has to unwind after the parent died, before the worker is ended
PR_SET_PDEATHSIG = 1   # <linux/prctl.h>
# The signal that says the parent died. Not SIGTERM, which the pool sends to workers of a living
# parent, and not decided by os.getppid() in the handler: the kernel also signals when the *thread*
# that started the worker ends, which in a killed parent can come before the worker is reparented.
PARENT_DIED = signal.SIGUSR1

_PARENT_PID: int | None = None
_ORPHANED = threading.Event()   # set once SystemExit has been raised for the parent's death
_IDLE = False                   # a pool worker waiting for its next task


def process_pool(max_workers: int, initializer=None, initargs: tuple = ()) -> ProcessPoolExecutor:
    """A pool of spawned workers (spawn, not fork: a fork of a process that has loaded torch, OpenMP or
    an OpenGL context can deadlock on their locks) that die with this process.

    ``initializer(*initargs)`` runs in each worker after the death watch is set up. Create and use the
    pool from one thread that outlives it (Linux sends the parent-death signal when the *thread* that
    started a worker ends; ``ProcessPoolExecutor`` starts workers in the thread that submits).
    """
    return _PoolDyingWithParent(max_workers=max_workers, mp_context=get_context("spawn"),
                                initializer=_start_worker, initargs=(os.getpid(), initializer, initargs))


class _PoolDyingWithParent(ProcessPoolExecutor):
    """Runs every task through :func:`_run_task` (``map`` submits through ``submit`` too)."""

    def submit(self, fn, /, *args, **kwargs):
        return super().submit(_run_task, fn, *args, **kwargs)


def _run_task(fn, *args, **kwargs):
    """In a worker: run one task, unless the parent is gone; leave as soon as a task has unwound for
    the parent's death. The task queue's pipe still holds tasks the dead parent queued, and the pool's
    loop, having caught the ``SystemExit``, would start the next one."""
    global _IDLE
    if os.getppid() != _PARENT_PID:
        os._exit(128 + signal.SIGTERM)
    _IDLE = False
    try:
        return fn(*args, **kwargs)
    finally:
        if _ORPHANED.is_set():
            os._exit(128 + signal.SIGTERM)
        _IDLE = True


def _start_worker(parent_pid: int, initializer, initargs: tuple) -> None:
    global _IDLE
    _IDLE = True
    die_with_parent(parent_pid)
    if initializer is not None:
        initializer(*initargs)


def die_with_parent(parent_pid: int, use_prctl: bool = True) -> threading.Thread:
    """In a child process: exit cleanly when the process ``parent_pid`` dies; returns the watchdog thread.

    Installs the signal handlers (:func:`_on_parent_death`, :func:`_on_sigterm`), asks the kernel for
    :data:`PARENT_DIED` on the parent's death (``use_prctl``, Linux only) and starts the watchdog
    thread. Call it from the child's main thread.
    """
    global _PARENT_PID
    _PARENT_PID = parent_pid
    signal.signal(signal.SIGTERM, _on_sigterm)
    signal.signal(PARENT_DIED, _on_parent_death)
    if use_prctl:
        set_parent_death_signal(PARENT_DIED)
    watchdog = threading.Thread(target=_watch_parent, args=(parent_pid,), name="die-with-parent", daemon=True)
    watchdog.start()
    return watchdog


def set_parent_death_signal(signum: int) -> bool:
    """Ask the kernel to send ``signum`` to this process when its parent dies (Linux ``prctl``).

    Returns False where that is not available (not Linux, no libc found), leaving the watchdog alone.

    >>> set_parent_death_signal(0)   # 0 clears it again
    True
    """
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        return libc.prctl(PR_SET_PDEATHSIG, int(signum), 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def _on_parent_death(signum, frame) -> None:
    """The parent died (:data:`PARENT_DIED`, from the kernel or the watchdog): unwind the main thread
    with ``SystemExit``, once — both death watches signal, and the second must not interrupt the
    clean-up the first started."""
    if _IDLE:   # a pool worker between tasks: nothing to clean up, and a normal exit can take seconds
        os._exit(128 + signal.SIGTERM)
    if _ORPHANED.is_set():
        return
    _ORPHANED.set()
    raise SystemExit(128 + signal.SIGTERM)


def _on_sigterm(signum, frame) -> None:
    """SIGTERM (the pool's own ``terminate``, or anyone's ``kill``): unwind with ``SystemExit``, every
    time (a worker that caught the first inside a task needs a second), unless the worker is already
    unwinding for its parent's death."""
    if _ORPHANED.is_set():
        return
    raise SystemExit(128 + signum)


def check_orphaned() -> None:
    """In a worker whose parent died: raise ``SystemExit`` (again). Call it where a long task can stop.

    The first ``SystemExit`` can be lost: one landing in an at-fork hook, run while a subprocess such
    as ffmpeg starts, is printed as "Exception ignored", and a library's bare ``except:`` around an
    import swallows it; the task goes on.

    >>> check_orphaned()   # the parent of this process lives: nothing happens
    """
    if _ORPHANED.is_set():
        raise SystemExit(128 + signal.SIGTERM)


_FORCED_EXIT_CLEANUPS: list = []


def at_forced_exit(cleanup) -> None:
    """Have ``cleanup()`` run (from the watchdog thread) when the watchdog must end this process
    because its task did not unwind within :data:`GRACE_S` — e.g. remove the temporary files of a
    task that is still writing. A no-op in a process without a death watch."""
    _FORCED_EXIT_CLEANUPS.append(cleanup)


def _watch_parent(parent_pid: int) -> None:
    """Poll the parent; once it is gone, signal :data:`PARENT_DIED` and end the process after the grace time.

    ``os.getppid()`` changes when the parent dies (the child is reparented to init or a subreaper);
    a parent that died before the watch started is caught the same way.
    """
    while os.getppid() == parent_pid:
        time.sleep(POLL_S)
    os.kill(os.getpid(), PARENT_DIED)
    time.sleep(GRACE_S)
    for cleanup in _FORCED_EXIT_CLEANUPS:
        try:
            cleanup()
        except Exception:   # the process ends next whatever happens; one failed clean-up must not stop the rest
            pass
    os._exit(128 + signal.SIGTERM)
