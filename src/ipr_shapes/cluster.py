"""A connection to an existing Ray cluster (``ipr-shapes batch --ray ADDRESS``), checked before any work.

Ray is an optional extra (``pip install 'ipr-shapes[ray]'``): this module imports it only when a
connection is asked for, and every way a connection can fail is one IprError line (Ray missing,
an address that is not one, a cluster that cannot be reached, one without CPUs) within a bounded
time, instead of Ray's own retries, which wait minutes.

The driver's ``ipr`` package is sent to the workers with the connection (Ray's ``runtime_env``
``py_modules``), so every node runs the driver's code; the packages ipr needs (mujoco, numpy, ...)
must be installed on every node.
"""

from __future__ import annotations

import contextlib
import re
import signal
import socket
import threading
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType

from ipr_shapes.errors import IprError

#: The command that installs Ray with ipr, named in every "Ray is missing" message.
RAY_INSTALL = "pip install 'ipr-shapes[ray]'"
#: Seconds to wait for the head's port to accept a TCP connection.
REACH_TIMEOUT_S = 10.0
#: Seconds ``ray.init`` may take once the port answers (Ray itself retries for minutes).
CONNECT_TIMEOUT_S = 60.0

_ADDRESS = re.compile(
    r"^(?P<client>ray://)?(?P<host>[A-Za-z0-9](?:[A-Za-z0-9.\-]*[A-Za-z0-9])?|\[[0-9A-Fa-f:.]+\])"
    r":(?P<port>[0-9]{1,5})$"
)


@dataclass(frozen=True)
class RayAddress:
    """A parsed ``--ray`` address.

    Attributes:
        text: as given (``auto``, ``HOST:PORT`` or ``ray://HOST:PORT``).
        host, port: the head's host and port (None for ``auto``: the cluster started on this
            machine by ``ray start``, or ``RAY_ADDRESS``).
        client: a Ray Client address (``ray://``), for a driver outside the cluster's network.
    """

    text: str
    host: str | None = None
    port: int | None = None
    client: bool = False


def parse_address(text: str) -> RayAddress:
    """``text`` as a RayAddress; IprError naming the accepted forms otherwise."""
    text = text.strip()
    if text == "auto":
        return RayAddress(text)
    match = _ADDRESS.match(text)
    port = int(match["port"]) if match else 0
    if match is None or not 1 <= port <= 65535:
        raise IprError(
            f"--ray {text!r}: not a Ray cluster address (fix: give 'auto', HOST:PORT as "
            "'ray start --head' printed it, e.g. 10.0.0.5:6379, or ray://HOST:10001 for Ray Client)"
        )
    return RayAddress(text, match["host"].strip("[]"), port, client=bool(match["client"]))


def import_ray() -> ModuleType:
    """The ``ray`` module; IprError saying how to install it when it is missing."""
    try:
        import ray
    except ImportError as error:
        raise IprError(
            f"--ray needs Ray, which is not installed ({error}) (fix: {RAY_INSTALL})"
        ) from None
    return ray


def check_reachable(address: RayAddress, timeout_s: float = REACH_TIMEOUT_S) -> None:
    """IprError unless the head's port accepts a TCP connection within ``timeout_s`` (s)."""
    if address.host is None:
        return
    try:
        with socket.create_connection((address.host, address.port), timeout=timeout_s):
            pass
    except OSError as error:
        reason = "timed out" if isinstance(error, TimeoutError) else (error.strerror or str(error))
        raise IprError(
            f"--ray {address.text}: cannot reach the Ray cluster ({reason} within "
            f"{timeout_s:g} s) (fix: start its head with 'ray start --head', check the host, "
            "the port and the firewall)"
        ) from None


class _Expired(BaseException):
    """A deadline passed: a BaseException, so that the retry loops it interrupts (Ray's catch
    Exception and try again) let it through."""


@contextlib.contextmanager
def _deadline(seconds: float, message: str) -> Iterator[None]:
    """Raise IprError(message) if the block runs longer than ``seconds`` (main thread only:
    elsewhere the block runs unbounded). A block waiting in compiled code is interrupted when
    that call returns to Python (Ray's connection attempts: at most 40 s each)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def expire(signum, frame):
        raise _Expired

    previous = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    except _Expired:
        raise IprError(message) from None
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


@contextlib.contextmanager
def connect(text: str, timeout_s: float = CONNECT_TIMEOUT_S) -> Iterator[ModuleType]:
    """Connect this process to the Ray cluster at ``text`` and yield the ``ray`` module;
    disconnect at the end. IprError (one line, before any work) when Ray is missing, the address
    is malformed, or the cluster cannot be reached or has no CPU within ``timeout_s`` (s)."""
    address = parse_address(text)
    ray = import_ray()
    check_reachable(address)
    import ipr_shapes

    package = str(Path(ipr_shapes.__file__).resolve().parent)
    failure = (
        f"--ray {address.text}: the Ray cluster did not accept this driver within "
        f"{timeout_s:g} s (fix: check that the address is the head's, as 'ray start --head' "
        "printed it, and that ray and Python have the same versions here and on the cluster)"
    )
    try:
        with _deadline(timeout_s, failure):
            try:
                ray.init(
                    address=address.text,
                    logging_level="warning",
                    log_to_driver=False,
                    runtime_env={"py_modules": [package]},
                )
            except IprError:
                raise
            except Exception as error:  # noqa: BLE001 - Ray raises many kinds; each is one line
                first = (str(error).strip().splitlines() or [type(error).__name__])[0]
                raise IprError(
                    f"--ray {address.text}: cannot connect to the Ray cluster: {first} (fix: start "
                    "its head with 'ray start --head' and give the address it printed)"
                ) from None
            cpus = ray.cluster_resources().get("CPU", 0.0)
        if cpus < 1:
            raise IprError(
                f"--ray {address.text}: the Ray cluster has no CPU to run scenes on (fix: start "
                "workers with 'ray start --address HEAD:PORT' and at least one CPU)"
            )
        yield ray
    finally:
        with contextlib.suppress(Exception):
            ray.shutdown()
