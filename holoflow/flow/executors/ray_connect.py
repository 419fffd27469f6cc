"""Joining an existing Ray cluster: its authentication token, and a bounded wait (docs/scale.md).

Ray (2.5x and later) turns token authentication on for a cluster started with a token at hand, and a
driver must then present the same token. Ray finds it, in this order, in ``$RAY_AUTH_TOKEN``, in the
file ``$RAY_AUTH_TOKEN_PATH`` names, or in ``~/.ray/auth_token``; but a driver only sends it when
``RAY_AUTH_MODE=token``, which Ray sets by itself for ``address="auto"`` and never for an explicit
``HOST:PORT``. :func:`use_token` does the same for an explicit address. The token itself is never
read here: it is not written into the store, a record, a log or a message.

A cluster that is gone (an address file left by a stopped ``ray start``, a head that is down) makes
``ray.init`` retry for ten minutes and more; :func:`wait_for_cluster` first waits for the head's port
to accept a TCP connection, up to a bound, and fails in one line when it never does.
"""

from __future__ import annotations

import os
import socket
import sys
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path

from ..pipeline import PipelineError

#: seconds to wait for a cluster's head to answer (``--connect-timeout``)
CONNECT_TIMEOUT_S = 60.0


def token_source() -> str | None:
    """Where Ray will read a token from (words, never the token), or None when there is none."""
    if os.environ.get("RAY_AUTH_TOKEN", "").strip():
        return "$RAY_AUTH_TOKEN"
    path = os.environ.get("RAY_AUTH_TOKEN_PATH")
    if path:
        return f"$RAY_AUTH_TOKEN_PATH ({path})" if os.path.isfile(path) else None
    default = Path.home() / ".ray" / "auth_token"
    return str(default) if default.is_file() else None


def use_token(address: str | None) -> str | None:
    """Before ``ray.init(address)``: send the token to an explicit address when one is at hand and
    ``RAY_AUTH_MODE`` is unset (set to ``token`` here, so the driver's Ray reads it). Returns where
    the token comes from, or None (no token, or the user chose a mode)."""
    if address in (None, "auto", "local") or "RAY_AUTH_MODE" in os.environ:
        return None
    source = token_source()
    if source is not None:
        os.environ["RAY_AUTH_MODE"] = "token"
        if "ray._raylet" in sys.modules:  # Ray already read its config in this process
            sys.modules["ray._raylet"].Config.initialize("")
    return source


def head_address(address: str) -> tuple[str, int]:
    """(host, port) the driver will connect to for ``address`` (``auto`` reads Ray's address file,
    ``$RAY_ADDRESS`` wins as in Ray; ``ray://HOST:PORT`` is the Ray client's port)."""
    if address.startswith("ray://"):
        host, _, port = address[6:].partition("/")[0].rpartition(":")
        return host, int(port or 10001)
    from ray._private import services

    try:
        resolved = services.canonicalize_bootstrap_address(address)
    except (ConnectionError, ValueError) as e:
        raise PipelineError(
            f"--address {address}: {str(e).splitlines()[0]}; fix: start the cluster "
            f"(`ray start --head`) or pass --address HOST:PORT"
        ) from None
    if resolved is None:
        raise PipelineError(
            f"--address {address}: no Ray cluster is known on this node; fix: start one "
            f"(`ray start --head`) or pass --address HOST:PORT"
        )
    host, _, port = resolved.rpartition(":")
    return host.strip("[]"), int(port)


def wait_for_cluster(address: str, timeout: float = CONNECT_TIMEOUT_S) -> None:
    """Wait until the head of ``address`` accepts a TCP connection, up to ``timeout`` seconds (one
    try at least); a PipelineError line when it never does."""
    host, port = head_address(address)
    deadline = time.monotonic() + max(0.0, timeout)
    while True:
        try:
            socket.create_connection((host, port), timeout=max(0.5, min(5.0, deadline - time.monotonic()))).close()
            return
        except OSError as e:
            why = e.strerror or type(e).__name__
        if time.monotonic() >= deadline:
            break
        time.sleep(min(1.0, max(0.0, deadline - time.monotonic())))
    came = f" (from --address {address}: Ray's address file or $RAY_ADDRESS)" if address == "auto" else ""
    raise PipelineError(
        f"no Ray cluster answers at {host}:{port}{came} after {timeout:g} s ({why}); fix: "
        f"start it (`ray start --head`), check --address, or raise --connect-timeout"
    )


def join_failed(address: str, e: BaseException, token: str | None) -> PipelineError:
    """One line for a ``ray.init`` that reached the head but could not join it (most often a token
    the cluster wants and the driver lacks, or a token it does not accept)."""
    first = (str(e).strip().splitlines() or [""])[0][:200]
    if token is None and token_source() is None:
        hint = (
            "if the cluster uses token authentication (Ray's default when its head had a token), give "
            "this driver the cluster's token in $RAY_AUTH_TOKEN, $RAY_AUTH_TOKEN_PATH or ~/.ray/auth_token"
        )
    else:
        hint = (
            f"the token from {token or token_source()} was sent: check it is the cluster's "
            f"(`ray get-auth-token` on the head prints it)"
        )
    return PipelineError(f"cannot join the Ray cluster at {address} ({type(e).__name__}: {first}); fix: {hint}")


@contextmanager
def held_stderr():
    """Hold back what this process writes to file descriptor 2 (Ray's C++ client warns once a second
    while a join is refused); yields a dict whose ``text`` is what was written, set on exit."""
    sys.stderr.flush()
    saved = os.dup(2)
    box: dict[str, str] = {}
    with tempfile.TemporaryFile() as tmp:
        os.dup2(tmp.fileno(), 2)
        try:
            yield box
        finally:
            sys.stderr.flush()
            os.dup2(saved, 2)
            os.close(saved)
            tmp.seek(0)
            box["text"] = tmp.read().decode(errors="replace")
