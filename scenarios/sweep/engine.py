"""Where a sweep's tasks run: on Ray (a local instance, or a cluster), or in this process.

A task is a module-level function of the project and plain arguments (seeds, settings,
paths, arrays); it builds its own model. Both engines run the same function on the same
arguments, so they give the same numbers; results come back as tasks finish.

* ``ray``: with ``RAY_ADDRESS`` set, ``ray.init()`` joins that cluster; without it, a Ray
  instance on this machine sized to its cores, without the dashboard. Inside a Ray task
  (a sweep of a study that itself fans out) the running instance is used.
* ``local``: one task after the other in this process (tests, debugging, no Ray at all).

:func:`default_engine` is what a study uses for its own draws: ``PKM_ENGINE`` (``local`` or
``ray``) when set, else Ray when it is already running or ``RAY_ADDRESS`` names a cluster,
else in-process: a machine without a cluster runs everything locally, as before.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

ENGINES = ("ray", "local")
ENV_ENGINE = "PKM_ENGINE"


class EngineError(RuntimeError):
    """The engine cannot start (Ray missing, a cluster that does not answer)."""


@dataclass(frozen=True)
class Outcome:
    """One task's result, or why the engine could not produce it (a worker that died)."""

    index: int
    value: Any = None
    error: str | None = None


class LocalEngine:
    """Each task in this process, in order."""

    name = "local"

    def map(self, fn: Callable[..., Any], args: Sequence[tuple[Any, ...]]) -> Iterator[Outcome]:
        for i, a in enumerate(args):
            yield Outcome(i, fn(*a))

    def close(self) -> None:
        pass


class RayEngine:
    """Tasks on Ray; starts (and on ``close`` stops) a local instance unless one runs."""

    name = "ray"

    def __init__(self, num_cpus: int | None = None) -> None:
        try:
            import ray
        except ImportError as exc:  # pragma: no cover - ray is a dependency
            raise EngineError("the ray engine needs the 'ray' package (pip install ray)") from exc
        self._ray = ray
        self._started = False
        if ray.is_initialized():
            return
        try:
            if os.environ.get("RAY_ADDRESS"):
                ray.init(log_to_driver=False)  # joins the cluster RAY_ADDRESS names
            else:
                ray.init(
                    num_cpus=num_cpus or os.cpu_count() or 1,
                    include_dashboard=False,
                    log_to_driver=False,
                )
        except Exception as exc:
            where = os.environ.get("RAY_ADDRESS") or "a local instance"
            raise EngineError(f"ray could not start ({where}): {exc}{_auth_hint(exc)}") from exc
        self._started = True

    @property
    def cluster(self) -> dict[str, Any]:
        res = self._ray.cluster_resources()
        return {"address": os.environ.get("RAY_ADDRESS"), "cpus": res.get("CPU")}

    def map(self, fn: Callable[..., Any], args: Sequence[tuple[Any, ...]]) -> Iterator[Outcome]:
        ray = self._ray
        remote = ray.remote(num_cpus=1, max_retries=0)(fn)
        refs = {remote.remote(*a): i for i, a in enumerate(args)}
        pending = list(refs)
        try:
            while pending:
                done, pending = ray.wait(pending, num_returns=1)
                for ref in done:
                    try:
                        yield Outcome(refs[ref], ray.get(ref))
                    except ray.exceptions.RayError as exc:  # the worker, not the study
                        yield Outcome(refs[ref], error=f"{type(exc).__name__}: {exc}")
        finally:
            for ref in pending:  # interrupted: do not leave tasks running
                with contextlib.suppress(Exception):
                    ray.cancel(ref, force=True)

    def close(self) -> None:
        if self._started:
            self._ray.shutdown()
            self._started = False


def _auth_hint(exc: Exception) -> str:
    """What to do when a cluster asks for its token (Ray's own message says where it looks)."""
    text = f"{type(exc).__name__} {exc}"
    if "Authentication" not in text and "AuthToken" not in text:
        return ""
    return (
        "\n  the cluster uses token authentication: run with RAY_AUTH_MODE=token and the "
        "head's token (its ~/.ray/auth_token copied to this machine, RAY_AUTH_TOKEN_PATH or "
        "RAY_AUTH_TOKEN); see docs/guide.md, 'Sweeps on a cluster'"
    )


def make_engine(name: str, num_cpus: int | None = None) -> LocalEngine | RayEngine:
    if name == "local":
        return LocalEngine()
    if name == "ray":
        return RayEngine(num_cpus)
    raise EngineError(f"unknown engine '{name}'; known: {list(ENGINES)}")


def default_engine() -> LocalEngine | RayEngine:
    """The engine a study uses for its own draws (see the module's docstring)."""
    chosen = os.environ.get(ENV_ENGINE, "").strip().lower()
    if chosen:
        return make_engine(chosen)
    if os.environ.get("RAY_ADDRESS"):
        return RayEngine()
    try:
        import ray
    except ImportError:  # pragma: no cover - ray is a dependency
        return LocalEngine()
    return RayEngine() if ray.is_initialized() else LocalEngine()


@contextlib.contextmanager
def engine_env(name: str) -> Iterator[None]:
    """``PKM_ENGINE=name`` for the block, so a study's own draws use the same engine."""
    old = os.environ.get(ENV_ENGINE)
    os.environ[ENV_ENGINE] = name
    try:
        yield
    finally:
        if old is None:
            os.environ.pop(ENV_ENGINE, None)
        else:
            os.environ[ENV_ENGINE] = old
