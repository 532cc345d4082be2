"""Where independent pieces of work run: here, one after another or on threads (``local``), or as tasks on
a Ray cluster (``ray``, the optional ``ray`` extra): a local one started for the command, or
the cluster at ``--address``.

Each Ray task asks for the CPUs of one local piece of work (:func:`task_cpus`) and runs with
the same thread counts, so results equal the local ones; a cluster with more CPUs runs more
tasks at once. Work that needs an expensive object first (an ONNX Runtime session) runs on
actors that make it once each (:meth:`Engine.map_stateful`).
"""

from __future__ import annotations

import os
import socket
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from functools import partial
from typing import Any

from tqdm import tqdm

from dataset_tools.infra.errors import OptionError

ENGINES = ("local", "ray")


def task_cpus() -> int:
    """The CPUs a piece of work uses here: the entry point's thread count, else every usable CPU."""
    from dataset_tools.infra.threads import usable_cpus

    return int(os.environ.get("OMP_NUM_THREADS") or usable_cpus())


@dataclass(frozen=True)
class Engine:
    """``name``: ``local`` or ``ray``; ``address``: a Ray cluster (None: start a local one);
    ``cpus``: CPUs per task (default :func:`task_cpus`)."""

    name: str = "local"
    address: str | None = None
    cpus: int | None = None

    def __post_init__(self) -> None:
        if self.name not in ENGINES:
            raise OptionError("{engine}: choose local or ray.", engine=self.name)
        if self.address is not None and self.name != "ray":
            raise OptionError("{address} names a Ray cluster; pass it with {engine}.", engine="ray")

    def map(
        self, fn: Callable[[Any], Any], items: Sequence[Any], *, desc: str = "tasks", progress: bool = True
    ) -> list[Any]:
        """``[fn(x) for x in items]``, in order; for ``ray``, ``fn`` must be importable by the
        workers (a module function, or a partial of one). The first task that fails raises its
        error here."""
        if self.name == "local" or not items:
            return [fn(x) for x in tqdm(items, desc=desc, unit="task", disable=not progress, leave=False)]
        ray = _init_ray(self.address)
        remote = ray.remote(**self._resources())(_call)
        return _gather(ray, [remote.remote(fn, x) for x in items], desc, progress)

    def map_stateful(
        self,
        setup: Callable[[], Any],
        fn: Callable[[Any, Any], Any],
        items: Sequence[Any],
        *,
        local_state: Any = None,
        threads: int = 1,
        desc: str = "items",
        progress: bool = True,
    ) -> list[Any]:
        """``[fn(state, x) for x in items]``, in order, where each worker makes ``state = setup()``
        once: here one state (``local_state`` when given: one already made), shared by
        ``threads`` threads (more than one only for an ``fn`` that is safe to call at once and
        spends its time outside the GIL); on Ray one actor per task slot of the cluster (its
        CPUs over the CPUs of a task, at most one per item), the items spread over them.
        ``setup`` and ``fn`` must be importable by the workers, as for :meth:`map`."""
        if self.name == "local" or not items:
            state = setup() if local_state is None else local_state
            bar = partial(tqdm, total=len(items), desc=desc, unit="item", disable=not progress, leave=False)
            if threads <= 1:
                return [fn(state, x) for x in bar(items)]
            with ThreadPoolExecutor(threads) as pool:
                return list(bar(pool.map(partial(fn, state), items)))
        ray = _init_ray(self.address)
        resources = self._resources()
        slots = int(ray.cluster_resources().get("CPU", 1)) // resources["num_cpus"]
        actors = [ray.remote(**resources)(_Worker).remote(setup) for _ in range(max(1, min(slots, len(items))))]
        try:
            return _gather(
                ray, [actors[k % len(actors)].run.remote(fn, x) for k, x in enumerate(items)], desc, progress
            )
        finally:
            for actor in actors:
                ray.kill(actor)

    def _resources(self) -> dict:
        """Ray options of one task or actor: the CPUs of a local piece of work, the same thread counts."""
        cpus = self.cpus or task_cpus()
        env = {
            "OMP_NUM_THREADS": str(cpus),
            "MKL_NUM_THREADS": str(cpus),
            "NUMBA_NUM_THREADS": str(cpus),
            "OMP_WAIT_POLICY": os.environ.get("OMP_WAIT_POLICY", "PASSIVE"),
        }
        return {"num_cpus": cpus, "runtime_env": {"env_vars": env}}


def _gather(ray, refs: list, desc: str, progress: bool) -> list[Any]:
    """The results of ``refs`` in order, with a progress bar; the first failure raises its own error."""
    pending = list(refs)
    with tqdm(total=len(refs), desc=f"{desc} (ray)", unit="task", disable=not progress, leave=False) as bar:
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            bar.update(len(done))
    try:
        return ray.get(refs)
    except ray.exceptions.RayTaskError as e:  # the task's own error, without the remote traceback
        raise e.cause from None


def _call(fn: Callable[[Any], Any], item: Any) -> Any:
    """A Ray task: ``fn(item)`` (``fn`` travels by reference, so any importable callable works)."""
    return fn(item)


class _Worker:
    """A Ray actor holding ``setup()``'s result for the items sent to it (made by the first
    item, so that a failing setup is that item's error, raised as any task's)."""

    def __init__(self, setup: Callable[[], Any]):
        self.setup, self.state = setup, None

    def run(self, fn: Callable[[Any, Any], Any], item: Any) -> Any:
        if self.setup is not None:
            self.state, self.setup = self.setup(), None
        return fn(self.state, item)


CONNECT_TIMEOUT_S = 5.0


def _require_reachable(address: str, timeout: float = CONNECT_TIMEOUT_S) -> None:
    """Refuse a cluster address (``HOST:PORT`` or ``ray://HOST:PORT``) where nothing accepts a
    connection within ``timeout`` seconds: Ray itself retries for minutes."""
    host, _, port = address.removeprefix("ray://").rpartition(":")
    if not host or not port.isdigit():
        raise OptionError("{address}: give the cluster's HOST:PORT, such as 10.0.0.1:6379.", address=address)
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=timeout).close()
    except (OSError, ValueError) as e:
        why = e.strerror if isinstance(e, OSError) and e.strerror else str(e) or type(e).__name__
        raise OptionError(
            f"{{address}}: no Ray cluster answers there ({why}); start one with `ray start --head` or leave "
            "{address} out for a local one.",
            address=address,
        ) from None


def _init_ray(address: str | None):
    try:
        import ray
    except ImportError:
        raise OptionError("{engine} needs Ray; install it with `pip install -e .[ray]`.", engine="ray") from None
    if address is not None and address != "auto":
        _require_reachable(address)
    if not ray.is_initialized():
        try:
            ray.init(address=address, include_dashboard=False, log_to_driver=False, configure_logging=False)
        except ConnectionError as e:
            raise OptionError(
                f"{{address}}: no Ray cluster answers there ({e}); start one with `ray start --head` or leave "
                "{address} out for a local one.",
                address=address,
            ) from None
    return ray
