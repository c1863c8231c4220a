"""Where the heavy steps run: this machine's process pool (the default) or a Dask distributed cluster.

``render``, ``physics protocol``, ``bodies`` and ``power`` take ``--scheduler`` (or the
:data:`ENV_VAR` environment variable):

- not given: nothing changes, each step uses its own local process pool (``stimuli.workers``);
- ``local:N``: a ``LocalCluster`` of N worker processes (one thread each) on this machine;
- ``tcp://HOST:PORT``: a running ``dask scheduler`` and its ``dask worker`` s.

Each task is submitted under a key made of the step's existing input hash (a clip's ``inputs_hash``,
a COM motion's or a body's cache key), so one task asked twice (two clients, a retry) runs once.
Tasks return their results (file bytes, rows, bodies) to the client, which writes them atomically: the
workers need no shared filesystem for outputs. A worker that dies mid-task has its task rerun on
another worker by the scheduler (``distributed.scheduler.allowed-failures``, 3 by default); a task
that raises is retried :data:`RETRIES` times. This module imports neither ``stimuli`` nor ``dask``
until a scheduler is used.

>>> parse_scheduler("local:2")
Scheduler(address=None, local_workers=2)
>>> parse_scheduler("tcp://127.0.0.1:8786").address
'tcp://127.0.0.1:8786'
"""

from __future__ import annotations

import logging
import os
import re
from contextlib import contextmanager
from dataclasses import dataclass

ENV_VAR = "SHAPEMOTION_SCHEDULER"
RETRIES = 2            # a task that raises (a worker's full temporary disk) is tried this many more times
CONNECT_TIMEOUT_S = 10  # how long a tcp:// scheduler has to answer, and to have at least one worker
MAX_LOCAL_WORKERS = 256
SCHEDULER_METAVAR = "tcp://HOST:PORT|local:N"
SCHEDULER_HELP = ("run the tasks on a Dask cluster: a 'dask scheduler' address, or local:N worker processes "
                  f"(default: ${ENV_VAR}, else this machine's process pool; see docs/readme_distributed.md)")
EXPECTED = "expected tcp://HOST:PORT (a running 'dask scheduler') or local:N (N worker processes on this machine)"


class SchedulerError(ValueError):
    """A malformed or unreachable scheduler; the commands report it as a user error (exit 2)."""


@dataclass(frozen=True)
class Scheduler:
    """A Dask cluster to run on: a scheduler's ``address`` or a local cluster of ``local_workers``."""

    address: str | None = None
    local_workers: int | None = None


def parse_scheduler(text: str, where: str = "--scheduler ") -> Scheduler:
    """A scheduler spec, checked; ``where`` (the option or variable) starts the error message.

    >>> parse_scheduler("tcp://cluster-head:8786").address
    'tcp://cluster-head:8786'
    >>> parse_scheduler("local:0")
    Traceback (most recent call last):
    ...
    shapemotion.execution.SchedulerError: --scheduler local:0: N must be a whole number from 1 to 256
    """
    text = text.strip()
    local = re.fullmatch(r"local:(\S+)", text)
    if local:
        n = local.group(1)
        if not n.isdigit() or not 1 <= int(n) <= MAX_LOCAL_WORKERS:
            raise SchedulerError(f"{where}{text}: N must be a whole number from 1 to {MAX_LOCAL_WORKERS}")
        return Scheduler(local_workers=int(n))
    remote = re.fullmatch(r"tcp://([A-Za-z0-9.\-_]+|\[[0-9A-Fa-f:]+\]):(\d+)", text)
    if remote:
        port = int(remote.group(2))
        if not 1 <= port <= 65535:
            raise SchedulerError(f"{where}{text}: port {port} is not between 1 and 65535")
        return Scheduler(address=text)
    raise SchedulerError(f"{where}{text!r}: {EXPECTED}")


def chosen_scheduler(option: str | None) -> Scheduler | None:
    """The scheduler of a command: its ``--scheduler`` option, else :data:`ENV_VAR`, else None
    (the local process pool). An empty value counts as not given.

    >>> chosen_scheduler(None) is None or ENV_VAR in os.environ
    True
    """
    if option is not None and option.strip():
        return parse_scheduler(option)
    value = os.environ.get(ENV_VAR, "").strip()
    return parse_scheduler(value, f"{ENV_VAR}=") if value else None


def scheduler_option(option: str | None, error=SchedulerError) -> Scheduler | None:
    """:func:`chosen_scheduler`, and a ``tcp://`` one answering with workers, before a command writes
    anything; problems are raised as ``error`` (the command's user-error class: exit 2)."""
    with errors_as(error):
        scheduler = chosen_scheduler(option)
        if scheduler is not None and scheduler.address is not None:
            with dask_client(scheduler, announce=lambda line: None):
                pass
        return scheduler


def unused_workers_warning(scheduler: Scheduler | None, workers: int | None) -> str | None:
    """The warning for ``--workers`` given with ``--scheduler`` (the cluster's workers run the tasks), else None.

    >>> print(unused_workers_warning(Scheduler(local_workers=4), 2))
    --workers 2 is not used with --scheduler: the cluster's 4 worker(s) run the tasks
    >>> unused_workers_warning(None, 2) is None
    True
    """
    if scheduler is None or workers is None:
        return None
    who = f"the cluster's {scheduler.local_workers} worker(s)" if scheduler.local_workers else "the cluster's workers"
    return f"--workers {workers} is not used with --scheduler: {who} run the tasks"


@contextmanager
def errors_as(error):
    """Re-raise a :class:`SchedulerError` (a bad spec, a scheduler that does not answer) as ``error``."""
    try:
        yield
    except SchedulerError as exc:
        raise error(str(exc)) from None


@contextmanager
def dask_client(scheduler: Scheduler, announce=print):
    """A ``distributed.Client`` on ``scheduler`` (a started local cluster is closed on leaving).

    ``announce`` is told where the work goes and the dashboard link. An unreachable scheduler, or one
    without workers, is a :class:`SchedulerError` naming the address.
    """
    from distributed import Client, LocalCluster

    if scheduler.local_workers is not None:
        # silence_logs: the nanny warns of each worker it stops at the end of a normal run
        with LocalCluster(n_workers=scheduler.local_workers, threads_per_worker=1, processes=True,
                          silence_logs=logging.ERROR, dashboard_address=":0") as cluster, \
                Client(cluster) as client:
            announce(f"dask: local cluster of {scheduler.local_workers} worker(s); {_dashboard(client)}")
            yield client
        return
    try:
        client = Client(scheduler.address, timeout=CONNECT_TIMEOUT_S)
    except (OSError, TimeoutError) as exc:
        raise SchedulerError(f"--scheduler {scheduler.address}: no Dask scheduler answered within "
                             f"{CONNECT_TIMEOUT_S} s ({exc}); {EXPECTED}") from None
    with client:
        try:
            client.wait_for_workers(1, timeout=CONNECT_TIMEOUT_S)
        except (OSError, TimeoutError):
            raise SchedulerError(f"--scheduler {scheduler.address}: the scheduler has no workers after "
                                 f"{CONNECT_TIMEOUT_S} s; start some with 'dask worker {scheduler.address}'") from None
        workers = len(client.scheduler_info()["workers"])
        announce(f"dask: scheduler {scheduler.address}, {workers} worker(s); {_dashboard(client)}")
        yield client


def _has_dashboard() -> bool:
    """The dashboard needs bokeh, which dask[distributed] does not install."""
    import importlib.util

    return importlib.util.find_spec("bokeh") is not None


def _dashboard(client) -> str:
    if "dashboard" not in client.scheduler_info().get("services", {}):
        return "the scheduler serves no dashboard"
    plots = "" if _has_dashboard() else " (its plots need bokeh: pip install bokeh)"
    return f"dashboard {client.dashboard_link}{plots}"


def run_tasks(client, fn, tasks: dict[str, tuple], desc: str, unit: str, progress: bool = True):
    """Submit ``fn(*args)`` for each ``key: args`` and yield ``(key, result)`` as tasks finish.

    Keys are the steps' input hashes: a key already known to the scheduler (another client, a retry)
    is not computed again. Leaving early (Ctrl-C, an error while writing a result) cancels what has
    not run; the caller's output then holds only the results it wrote.
    """
    from distributed import as_completed
    from tqdm import tqdm

    futures = [client.submit(fn, *args, key=key, pure=False, retries=RETRIES) for key, args in tasks.items()]
    bar = tqdm(total=len(futures), desc=desc, unit=unit, disable=not progress or not futures)
    try:
        for future in as_completed(futures):
            result = future.result()
            bar.update(1)
            yield future.key, result
    finally:
        bar.close()
        client.cancel([f for f in futures if not f.done()])


@contextmanager
def dask_pool(scheduler: Scheduler, announce=print):
    """A :class:`TaskPool` on ``scheduler``, for steps written against ``concurrent.futures``."""
    with dask_client(scheduler, announce) as client:
        pool = TaskPool(client)
        try:
            yield pool
        finally:
            client.cancel([f for f in pool.submitted if not f.done()])


class TaskPool:
    """``submit`` returning ``concurrent.futures.Future`` s that Dask settles: code that waits with
    ``concurrent.futures.as_completed`` or ``future.result()`` on a process pool works unchanged.

    ``then(result)`` runs on the client as each task finishes (it writes the files a task returned)
    and its return value is the future's result.
    """

    def __init__(self, client):
        self.client = client
        self.submitted = []

    def submit_keyed(self, key: str, fn, *args, then=None):
        from concurrent.futures import Future

        future = Future()
        remote = self.client.submit(fn, *args, key=key, pure=False, retries=RETRIES)
        remote.add_done_callback(lambda done: _settle(future, done, then))
        self.submitted.append(remote)
        return future


def _settle(future, done, then) -> None:
    """Copy a finished Dask future's outcome (through ``then``) into a ``concurrent.futures`` one."""
    try:
        result = done.result()
        future.set_result(then(result) if then else result)
    except BaseException as exc:   # the task's own error, or the write of its files, reaches whoever waits
        future.set_exception(exc)
