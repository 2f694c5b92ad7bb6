"""Where the one-task-per-scan batches of `v2c to-step`, `v2c synth`, `v2c bench` and `v2c train --recipe` run:
in this process, in a local process pool, or on a Ray cluster (docs/scale.md).

`run_tasks(fn, items, ...)` calls ``fn(item)`` once per item and yields ``(item, result, error)`` as the tasks
finish (exactly one of result / error is meaningful: error is None on success). A failing item is yielded with its
exception and does not stop the others. Items and results must be small and picklable: a task receives paths (scan
folders on a file system every worker sees at the same path) and writes its outputs there itself, it never ships
images through the driver.

Executors:

- ``local`` (default, no Ray needed): ``jobs`` <= 1 runs every task here, in order; ``jobs`` > 1 uses a pool of
  ``jobs`` spawned processes (spawned, not forked: forking a process whose OCCT / embree / torch thread pools run
  deadlocks), each set up once by ``initializer(*initargs)``.
- ``ray``: one Ray task per item on the cluster at ``address`` ("auto": the cluster `ray start` runs on this
  machine; "HOST:PORT": that head node; None: an already initialised Ray, else the cluster named by $RAY_ADDRESS,
  else a new local instance on this machine's cores). At most ``jobs`` tasks are in flight (None or 0: twice the
  cluster's CPUs), each on ``cpus_per_task`` CPUs. A task whose worker process dies is re-run up to ``max_retries``
  times (Ray's ``max_retries``); exceptions raised by ``fn`` are not retried (they are deterministic here). Workers
  run each task in the driver's working directory (so relative paths mean the same) and call the initializer once
  per worker process.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import socket
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from typing import Any, TypeVar

EXECUTORS = ("local", "ray")
#: How to get Ray, in the error raised when it is asked for and missing.
RAY_INSTALL_HINT = "pip install 'v2c[ray]' (or: pip install ray==2.60.0)"

T = TypeVar("T")
R = TypeVar("R")


class ExecutorError(RuntimeError):
    """An executor that cannot be used (Ray not installed, no cluster at the address); one line, no traceback."""


@dataclass(frozen=True)
class ExecutorConfig:
    """Where tasks run. kind: "local" or "ray"; address: Ray cluster (`connect_ray`); jobs: local worker
    processes (<= 1: this process) or most Ray tasks in flight (None: twice the cluster's CPUs); max_retries: Ray
    re-runs of a task whose worker died; cpus_per_task: Ray CPUs reserved per task (one thread per task)."""

    kind: str = "local"
    address: str | None = None
    jobs: int | None = 1
    max_retries: int = 3
    cpus_per_task: float = 1.0


def run_tasks(
    fn: Callable[[T], R],
    items: Iterable[T],
    executor: str | ExecutorConfig = "local",
    address: str | None = None,
    jobs: int | None = 1,
    initializer: Callable[..., Any] | None = None,
    initargs: tuple = (),
    max_retries: int = 3,
    cpus_per_task: float = 1.0,
) -> Iterator[tuple[T, R | None, BaseException | None]]:
    """Run ``fn`` on every item; yield ``(item, result, None)`` or ``(item, None, exception)`` as tasks finish.

    ``executor`` is "local" or "ray" (then address / jobs / max_retries / cpus_per_task apply), or an
    `ExecutorConfig` that carries them. ``initializer(*initargs)`` sets up each worker process (pool or Ray) once;
    it is not called for tasks run in this process. Raises `ExecutorError` before any task runs when the
    executor is unknown, Ray is missing or its cluster cannot be reached.
    """
    if isinstance(executor, ExecutorConfig):
        cfg = executor
    else:
        cfg = ExecutorConfig(
            kind=executor, address=address, jobs=jobs, max_retries=max_retries, cpus_per_task=cpus_per_task
        )
    items = list(items)
    if cfg.kind == "local":
        if cfg.jobs is None or cfg.jobs <= 1:
            return _run_here(fn, items)
        return _run_pool(fn, items, cfg.jobs, initializer, initargs)
    if cfg.kind == "ray":
        ray = ray_module()
        connect_ray(ray, cfg.address)
        return _run_ray(ray, fn, items, cfg, initializer, initargs)
    raise ExecutorError(f"executor {cfg.kind!r}: expected one of {', '.join(EXECUTORS)}")


# ------------------------------------------------------------------------------------------------- local


def _run_here(fn: Callable[[T], R], items: list[T]) -> Iterator[tuple[T, R | None, BaseException | None]]:
    for item in items:
        try:
            result = fn(item)
        except Exception as exc:  # noqa: BLE001 - a failing item is a result; the caller reports it
            yield item, None, exc
            continue
        yield item, result, None


def _run_pool(
    fn: Callable[[T], R], items: list[T], jobs: int, initializer: Callable[..., Any] | None, initargs: tuple
) -> Iterator[tuple[T, R | None, BaseException | None]]:
    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=jobs, mp_context=ctx, initializer=initializer, initargs=initargs) as pool:
        futures = {pool.submit(fn, item): item for item in items}
        for fut in as_completed(futures):
            exc = fut.exception()  # BrokenProcessPool when a worker died (e.g. a crash inside OCCT)
            yield futures[fut], (None if exc else fut.result()), exc


# --------------------------------------------------------------------------------------------------- Ray


def ray_module() -> Any:
    """The `ray` package, or `ExecutorError` saying how to install it."""
    try:
        import ray
    except ImportError:
        raise ExecutorError(
            f"--executor ray needs the Ray package, which is not installed: {RAY_INSTALL_HINT}"
        ) from None
    return ray


def connect_ray(ray: Any, address: str | None = None, probe_timeout_s: float = 5.0) -> None:
    """Connect this process to the Ray cluster at ``address`` unless Ray is already initialised here.

    address: "auto" (the cluster `ray start` runs on this machine), "HOST:PORT" (its head node), or None ($RAY_ADDRESS
    when set, else a new local instance: never a cluster that a stale /tmp/ray/ray_current_cluster names, which
    Ray would wait on for minutes). A given address is first probed with a TCP connection of at most
    ``probe_timeout_s`` seconds, so that an address where nothing answers fails at once."""
    if ray.is_initialized():
        return
    if address is None and not os.environ.get("RAY_ADDRESS"):
        address = "local"
    elif address is not None:
        _probe(address, probe_timeout_s)
    try:
        ray.init(address=address)
    except (ConnectionError, RuntimeError, ValueError) as exc:
        raise ExecutorError(
            f"no Ray cluster at --ray-address {address}: {_first_line(exc)}; start one with "
            "`ray start --head` (docs/scale.md)"
        ) from None


def _first_line(exc: BaseException) -> str:
    return (str(exc).splitlines() or [type(exc).__name__])[0].strip("'\"")


def _probe(address: str, timeout_s: float) -> None:
    """Raise `ExecutorError` when nothing accepts a TCP connection at the Ray cluster ``address`` names."""
    try:  # Ray's own reading of the address ("auto": the cluster file of `ray start`; localhost: this node's IP)
        from ray._private.services import canonicalize_bootstrap_address

        resolved = canonicalize_bootstrap_address(address)
    except ConnectionError as exc:
        raise ExecutorError(
            f"no Ray cluster at --ray-address {address}: {_first_line(exc)}; start one with "
            "`ray start --head` (docs/scale.md)"
        ) from None
    except Exception:  # noqa: BLE001 - a Ray without this helper: let ray.init judge the address
        return
    if not resolved:
        return
    host, _, port = resolved.rpartition(":")
    try:
        socket.create_connection((host, int(port)), timeout=timeout_s).close()
    except (OSError, ValueError):
        raise ExecutorError(
            f"no Ray cluster at --ray-address {address}: nothing answers at {resolved} "
            f"(a cluster stopped without `ray stop`?); start one with `ray start --head` "
            "(docs/scale.md)"
        ) from None


#: Initializers already run in this (worker) process, by (module, name, initargs).
_INITIALISED: set[tuple[str, str, str]] = set()


def _ray_call(fn: Callable[[T], R], init: tuple[Callable[..., Any] | None, tuple], cwd: str, item: T) -> R:
    """Body of every Ray task: set the worker up once (``init`` = (initializer, initargs)), then ``fn(item)`` in
    the driver's working directory."""
    initializer, initargs = init
    if initializer is not None:
        key = (initializer.__module__, initializer.__qualname__, repr(initargs))
        if key not in _INITIALISED:
            initializer(*initargs)
            _INITIALISED.add(key)
    here = os.getcwd()
    # A cluster whose nodes mount the data elsewhere has no such folder: then paths must be absolute.
    moved = os.path.isdir(cwd) and cwd != here
    if moved:
        os.chdir(cwd)
    try:
        return fn(item)
    finally:
        if moved:
            os.chdir(here)


def _unwrap(ray: Any, exc: BaseException) -> BaseException:
    """The exception ``fn`` raised (Ray wraps it in RayTaskError); Ray's own errors (a worker that died past its
    retries, ...) as they are."""
    if isinstance(exc, ray.exceptions.RayTaskError):
        cause = getattr(exc, "cause", None)
        if isinstance(cause, BaseException):
            return cause
    return exc


def _run_ray(
    ray: Any,
    fn: Callable[[T], R],
    items: list[T],
    cfg: ExecutorConfig,
    initializer: Callable[..., Any] | None,
    initargs: tuple,
) -> Iterator[tuple[T, R | None, BaseException | None]]:
    remote = ray.remote(_ray_call).options(
        num_cpus=cfg.cpus_per_task, max_retries=cfg.max_retries, retry_exceptions=False
    )
    if cfg.jobs:
        window = cfg.jobs
    else:
        window = max(1, 2 * int(ray.cluster_resources().get("CPU", 1) / max(cfg.cpus_per_task, 1e-9)))
    # fn, the initializer and its arguments go to the object store once, not once per task
    fn_ref = ray.put(fn)
    init_ref = ray.put((initializer, initargs))
    cwd = os.getcwd()
    todo = iter(items)
    pending: dict[Any, T] = {}

    def submit() -> None:
        for item in todo:
            pending[remote.remote(fn_ref, init_ref, cwd, item)] = item
            if len(pending) >= window:
                return

    submit()
    try:
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1)
            ref = done[0]
            item = pending.pop(ref)
            try:
                result, exc = ray.get(ref), None
            except Exception as e:  # noqa: BLE001 - the task's failure, reported by the caller
                result, exc = None, _unwrap(ray, e)
            submit()
            yield item, result, exc
    finally:
        for ref in pending:  # the caller stopped early: do not leave tasks running for nobody
            with contextlib.suppress(Exception):
                ray.cancel(ref)
