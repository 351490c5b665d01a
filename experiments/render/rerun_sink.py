"""Where a rerun recording goes (`--rerun`): a file, or a live viewer.

`--rerun TARGET` takes
  PATH            a `.rrd` file, written as ever (staged, then renamed; `viz.Recorder`);
  spawn           start a local rerun viewer (the `rerun` program rerun-sdk installs) and stream
                  the run to it live; a viewer already listening on rerun's port (9876) is used;
  connect         stream to a running viewer at rerun's default address,
                  rerun+http://127.0.0.1:9876/proxy;
  connect=ADDR    stream to the viewer (or `rerun --serve-grpc` proxy) at ADDR: HOST:PORT, a
                  port alone, or a URL rerun+http://HOST:PORT/proxy (also rerun:// and
                  rerun+https://), rerun's own convention (`rerun --connect`, `rr.connect_grpc`).
A file named `spawn` or `connect...` is given as `./spawn`.

The target is read and checked before the command does any work: a malformed address is a
`ConfigError`, and so is an address at which nothing accepts a connection (the check opens a TCP
connection; rerun's own connect would only say so after the run, having dropped its data).
This module does not import rerun (`viz` does); it names where the stream goes, `viz` opens it.
"""

from __future__ import annotations

import os
import shutil
import socket
import sys
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import urlsplit

from experiments.errors import ConfigError

__all__ = [
    "CONNECT_TIMEOUT_S",
    "DEFAULT_PORT",
    "Viewer",
    "check_reachable",
    "parse_rerun_target",
    "recording_file",
    "rerun_target",
    "viewer_program",
]

DEFAULT_PORT = 9876  # rerun's viewer and SDK default
CONNECT_TIMEOUT_S = 3.0  # a viewer that does not accept a connection in this long: refused
SCHEMES = ("rerun", "rerun+http", "rerun+https")
_OPTION = "--rerun"


@dataclass(frozen=True)
class Viewer:
    """A live viewer to stream a recording to. mode: "spawn" (start one, then connect) or
    "connect"; url: rerun's gRPC address, rerun+http://HOST:PORT/proxy; host, port: where it
    listens; given: the option's value as the user wrote it (for messages)."""

    mode: str
    url: str
    host: str
    port: int
    given: str

    def __post_init__(self) -> None:
        if self.mode not in ("spawn", "connect"):
            raise ValueError(f"mode: expected 'spawn' or 'connect', got {self.mode!r}")
        if not 0 < self.port < 65536:
            raise ValueError(f"port: expected 1-65535, got {self.port!r}")

    def __str__(self) -> str:
        return f"{_OPTION} {self.given}"


def _malformed(given: str, why: str) -> ConfigError:
    return ConfigError(
        f"{_OPTION} {given}: {why}; expected a file path, spawn, connect or connect=ADDR "
        "(HOST:PORT, a port, or rerun+http://HOST:PORT/proxy)"
    )


def _address(given: str, addr: str) -> tuple[str, str, int]:
    """(url, host, port) of a connect=ADDR address, or `ConfigError` naming it."""
    addr = addr.strip()
    if not addr:
        raise _malformed(given, "no address after connect=")
    if addr.isdigit():  # a port alone, as `rerun --connect PORT`
        addr = f"127.0.0.1:{addr}"
    url = addr if "://" in addr else f"rerun+http://{addr}/proxy"
    try:
        parts = urlsplit(url)
        port = parts.port
    except ValueError as exc:  # a port that is not a number or out of range
        raise _malformed(given, f"not a viewer address ({exc})") from None
    if parts.scheme not in SCHEMES:
        raise _malformed(given, f"scheme {parts.scheme!r} is not one of {', '.join(SCHEMES)}")
    if not parts.hostname:
        raise _malformed(given, "no host")
    if parts.path != "/proxy" or parts.query or parts.fragment:
        raise _malformed(given, "the URL's path must be /proxy (rerun's gRPC address)")
    if port is None:
        port = 443 if parts.scheme == "rerun+https" else DEFAULT_PORT
    if port == 0:
        raise _malformed(given, "port 0")
    host = parts.hostname
    shown = f"[{host}]" if ":" in host else host
    return f"{parts.scheme}://{shown}:{port}/proxy", host, port


def parse_rerun_target(text: str | Path | None) -> Path | Viewer | None:
    """The target of `--rerun TEXT` (see the module doc), without checking a viewer answers:
    None, a `Path`, or a `Viewer`. A malformed viewer address: `ConfigError` naming it."""
    if text is None or isinstance(text, Path):
        return text
    if text == "spawn":
        url = f"rerun+http://127.0.0.1:{DEFAULT_PORT}/proxy"
        return Viewer("spawn", url, "127.0.0.1", DEFAULT_PORT, text)
    if text == "connect":
        return Viewer("connect", *_address(text, f"127.0.0.1:{DEFAULT_PORT}"), text)
    if text.startswith("connect="):
        return Viewer("connect", *_address(text, text.removeprefix("connect=")), text)
    if text.startswith(("spawn=", "connect:")) or any(text.startswith(f"{s}://") for s in SCHEMES):
        raise _malformed(text, "not a viewer target")
    return Path(text)


def check_reachable(viewer: Viewer, timeout_s: float = CONNECT_TIMEOUT_S) -> None:
    """`ConfigError` naming the address when nothing accepts a TCP connection at it within
    `timeout_s` (refused, no route, unknown host, timed out)."""
    try:
        with socket.create_connection((viewer.host, viewer.port), timeout=timeout_s):
            pass
    except OSError as exc:
        why = exc.strerror or str(exc) or type(exc).__name__
        if isinstance(exc, TimeoutError):
            why = f"no answer in {timeout_s:g} s"
        raise ConfigError(
            f"{viewer}: no rerun viewer answers at {viewer.host}:{viewer.port} ({why}); "
            f"start one with `rerun` (it listens on {DEFAULT_PORT}), or use {_OPTION} spawn"
        ) from None


def viewer_program() -> str | None:
    """The `rerun` program `--rerun spawn` starts (beside this Python, as rerun-sdk installs
    it, or on PATH), or None."""
    here = Path(sys.executable).parent / "rerun"
    if here.is_file():
        return str(here)
    return shutil.which("rerun")


def _port_open(viewer: Viewer) -> bool:
    try:
        check_reachable(viewer, timeout_s=0.5)
    except ConfigError:
        return False
    return True


def rerun_target(text: str | Path | None) -> Path | Viewer | None:
    """`--rerun TEXT` read and checked before any work (the CLI's one call): None, a file path
    (the command's output checks apply to it as to any output), or a `Viewer` that answers
    (connect) or can be started (spawn: the `rerun` program is there, or a viewer already
    listens on its port). `ConfigError` naming the value otherwise."""
    target = parse_rerun_target(text)
    if not isinstance(target, Viewer):
        return target
    if target.mode == "connect":
        check_reachable(target)
    elif not _port_open(target):  # (a viewer already there is used as it is)
        if viewer_program() is None:
            raise ConfigError(
                f"{target}: the rerun viewer program (`rerun`, installed by rerun-sdk) is not "
                "found beside this Python nor on PATH"
            )
        if sys.platform.startswith("linux") and not _has_display():
            raise ConfigError(
                f"{target}: no display here (neither DISPLAY nor WAYLAND_DISPLAY is set), so "
                "a viewer window cannot open; start `rerun` where there is one and use "
                f"{_OPTION} connect=HOST:PORT, or give a file"
            )
    return target


def _has_display() -> bool:
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def recording_file(target: Path | Viewer | str | None) -> Path | str | None:
    """The file a target writes (None for a viewer or no recording): what the output checks
    look at."""
    return None if isinstance(target, Viewer) else target
