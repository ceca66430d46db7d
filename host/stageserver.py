"""How a simulated stage reaches a host: its controller on a loopback socket or a pty, the magnet's pose in a file.

``SocketServer`` and ``PtyServer`` run a simulated controller (``host.stagesim.SimController``,
or anything with ``flavor``, ``receive(bytes)``, ``step()`` and ``take_output()``) in a
thread and carry its bytes as a serial port would. ``PoseFile`` publishes the magnet's
pose for a capture in another process, which follows it through ``pose_file_motion``.
"""

from __future__ import annotations

import math
import os
import select
import socket
import threading
from pathlib import Path

import numpy as np

from fitgen.base.errors import InputError
from fitgen.base.fileio import write_target


class PoseFile:
    """The magnet's pose as one line of five numbers in a file, replaced atomically at every change (through a
    symlink, the file it leads to); InputError when ``path`` is a device, FIFO or socket."""

    def __init__(self, path: str | Path):
        self.path = write_target(path)

    def set_pose(self, pose) -> None:
        # not write_atomic: no fsync, since a pose changes many times a second and a crash loses only the simulation
        tmp = self.path.with_name(f".{self.path.name}.{os.getpid()}.tmp")
        try:
            tmp.write_text(",".join(repr(float(x)) for x in pose) + "\n")
            os.replace(tmp, self.path)
        except BaseException as exc:  # a signal between the two too: no temporary left beside the pose file
            tmp.unlink(missing_ok=True)
            if isinstance(exc, OSError):  # a folder or file that takes no writes (read-only, immutable, full)
                raise InputError(f"cannot write {self.path}: {exc.strerror or exc}") from None
            raise


def pose_file_motion(path: str | Path):
    """A ``SensorFeed.motion`` function reading a :class:`PoseFile` (re-read when it changes; rest until it exists)."""
    path = Path(path)
    cache = {"key": None, "pose": np.zeros(5)}

    def motion(t: float) -> np.ndarray:
        try:
            st = path.stat()
        except FileNotFoundError:
            return cache["pose"]
        key = (st.st_mtime_ns, st.st_size, st.st_ino)
        if key != cache["key"]:
            try:
                vals = [float(x) for x in path.read_text().split(",")]
            except (OSError, ValueError):
                return cache["pose"]  # replaced atomically, so this is a file not yet written: keep the last
            if len(vals) == 5 and all(math.isfinite(v) for v in vals):
                cache["key"], cache["pose"] = key, np.array(vals)
        return cache["pose"]

    return motion


class _Server:
    def __init__(self, controller, tick: float = 0.002):
        self.ctrl, self.tick = controller, tick
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self):
        self._thread = threading.Thread(target=self._run, name=f"stage-sim-{self.ctrl.flavor}", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5)
        self._close()

    def _close(self) -> None:
        pass

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.stop()


class SocketServer(_Server):
    """Serves the controller on 127.0.0.1 (one client at a time, as a serial port): ``url`` is socket://..."""

    def __init__(self, controller, port: int = 0, host: str = "127.0.0.1", **kw):
        super().__init__(controller, **kw)
        self.sock = socket.socket()
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            self.sock.bind((host, port))
        except (OSError, OverflowError) as exc:  # OverflowError: a port past 65535
            self.sock.close()
            raise InputError(f"cannot serve on {host}:{port}: {getattr(exc, 'strerror', None) or exc}") from None
        self.sock.listen(1)
        self.port = self.sock.getsockname()[1]
        self.url = f"socket://{host}:{self.port}"

    def _run(self) -> None:
        conn = None
        try:
            while not self._stop.is_set():
                if conn is None:
                    r, _, _ = select.select([self.sock], [], [], 0.05)
                    self.ctrl.step()
                    self.ctrl.take_output()  # nobody listens: what the controller says is lost, as on a wire
                    if r:
                        conn, _ = self.sock.accept()
                        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                    continue
                r, _, _ = select.select([conn], [], [], self.tick)
                if r:
                    try:
                        data = conn.recv(4096)
                    except OSError:
                        data = b""
                    if not data:  # the host went away; the controller carries on
                        conn.close()
                        conn = None
                        continue
                    self.ctrl.receive(data)
                self.ctrl.step()
                out = self.ctrl.take_output()
                if out:
                    try:
                        conn.sendall(out)
                    except OSError:
                        conn.close()
                        conn = None
        finally:
            if conn is not None:
                conn.close()

    def _close(self) -> None:
        self.sock.close()


class PtyServer(_Server):
    """Serves the controller on a pseudo-terminal: ``url`` is the path of its terminal side (/dev/pts/N)."""

    def __init__(self, controller, **kw):
        import tty

        super().__init__(controller, **kw)
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)  # no echo, no line editing, until a client sets its own mode
        self.url = os.ttyname(self.slave)  # keeping the slave open keeps the pty alive between clients

    def _run(self) -> None:
        while not self._stop.is_set():
            r, _, _ = select.select([self.master], [], [], self.tick)
            if r:
                try:
                    data = os.read(self.master, 4096)
                except OSError:
                    data = b""
                if data:
                    self.ctrl.receive(data)
            self.ctrl.step()
            out = self.ctrl.take_output()
            while out:
                try:
                    n = os.write(self.master, out)
                except OSError:
                    break
                out = out[n:]

    def _close(self) -> None:
        for fd in (self.master, self.slave):
            try:
                os.close(fd)
            except OSError:
                pass
