"""The live view's server: a hub that keeps the recent samples and a small HTTP server that pushes them.

``LiveHub.publish`` is called by the readout once per sample. It stores the sample in a
ring of the last ``backlog`` samples and numbers it (``seq`` = 1, 2, 3, ...); it takes no
lock that a viewer holds, does no I/O and encodes nothing, so a closed, slow or stalled
browser can never hold the readout back. ``LiveServer`` serves the page, its assets
(``host/static``, shipped with the package), ``/meta`` and ``/events``, a Server-Sent
Events stream: one thread per viewer polls the ring, encodes what is new once (cached
for the other viewers) and writes it in one piece, with a timeout on every write. A
viewer that falls further behind than the ring is told how many samples it lost and goes
on from the oldest one still held; one that stops reading is dropped after the timeout.
docs/live.md describes the page.
"""

from __future__ import annotations

import errno
import json
import math
import re
import secrets
import socket
import socketserver
import threading
import time
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib import resources
from urllib.parse import parse_qs, urlsplit

from fitgen.base.errors import InputError

STATIC_TYPES = {".html": "text/html; charset=utf-8", ".js": "text/javascript; charset=utf-8",
                ".css": "text/css; charset=utf-8", ".png": "image/png", ".svg": "image/svg+xml",
                ".txt": "text/plain; charset=utf-8"}
LIMIT = 512  # samples in one write to a viewer (about 340 kB)
DRAIN = 2.0  # s the streams have, when a run ends, to send the samples they have not yet
_NAME = re.compile(r"[A-Za-z0-9_-][A-Za-z0-9_.-]*\Z")  # one file name: no '/', no '..' prefix, no '%'


def _plain(obj):
    """numpy scalars and arrays as JSON sees them (json's ``default`` hook)."""
    if hasattr(obj, "tolist"):  # ndarray and numpy scalars
        return obj.tolist()
    raise TypeError(f"{type(obj).__name__} is not JSON serialisable")


def _finite(obj):
    """``obj`` with every non-finite float replaced by None (JSON has no NaN; the page shows a dash)."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    if hasattr(obj, "tolist"):
        return _finite(obj.tolist())
    return obj


def encode_sample(sample: dict) -> bytes:
    """One SSE event: ``id: <seq>`` and ``data: <sample as one line of JSON>``; NaN and inf become null."""
    try:
        text = json.dumps(sample, separators=(",", ":"), allow_nan=False, default=_plain)
    except ValueError:  # a non-finite reading (status -1): rare, so the slow path is fine
        text = json.dumps(_finite(sample), separators=(",", ":"), allow_nan=False, default=_plain)
    return b"id: %d\ndata: %s\n\n" % (sample["seq"], text.encode())


def _event(kind: str, data: dict) -> bytes:
    """An event without an id, so that a browser's Last-Event-ID stays the last sample's."""
    return b"event: %s\ndata: %s\n\n" % (kind.encode(), json.dumps(data, separators=(",", ":")).encode())


def view_meta(n_inputs: int, outputs, model_hash: str, source: str, rate: float | None) -> dict:
    """The ``meta`` a hub serves at /meta: inputs, outputs with their units, model, source, rate."""
    from fitgen.physics.pose import POSE_NAMES, POSE_UNITS

    return {"inputs": [f"v{k}" for k in range(1, n_inputs + 1)], "input_units": "V", "outputs": list(outputs),
            "units": [POSE_UNITS[POSE_NAMES.index(o)] for o in outputs], "model": model_hash[:12],
            "source": source, "rate": rate}


class LiveHub:
    """The last ``backlog`` samples, numbered; ``publish`` from the readout, ``collect`` from the viewers.

    Only publishers take the lock. Viewers read the ring without one: a slot is written
    before ``seq`` moves past it, and each sample carries its own ``seq``, so a viewer that
    finds a newer sample in a slot knows it was lapped (CPython makes each list store and
    attribute store atomic).
    """

    def __init__(self, meta: dict, backlog: int = 4096):
        if int(backlog) < 1:
            raise InputError(f"the live view's backlog must be >= 1 sample, got {backlog}")
        self.meta = dict(meta)
        self.meta_json = json.dumps(self.meta, default=_plain).encode()  # here, so bad meta fails at start
        self.backlog = int(backlog)
        self._ring: list = [None] * self.backlog
        self._enc: list = [None] * self.backlog  # (seq, encoded event), filled by the first viewer to need it
        self._seq = 0
        self._lock = threading.Lock()
        self.token = secrets.token_hex(6)  # tells a reconnecting page that the readout was restarted

    @property
    def seq(self) -> int:
        """The newest sample's number (0 before the first)."""
        return self._seq

    def publish(self, sample: dict) -> None:
        """Number ``sample`` (``sample["seq"]``) and keep it; O(1), no I/O, never waits for a viewer."""
        with self._lock:
            seq = self._seq + 1
            sample["seq"] = seq
            self._ring[seq % self.backlog] = sample
            self._seq = seq  # after the slot: a viewer that sees seq finds its sample

    def collect(self, last: int | None, limit: int = LIMIT) -> tuple[bytes, int]:
        """The events after sample ``last`` (None: all the ring holds), at most ``limit`` samples, and the new
        ``last``. Prefixed with a ``dropped`` event when samples after ``last`` are gone, or a ``reset`` event
        when ``last`` is ahead of this hub (the readout was restarted)."""
        head, n = self._seq, self.backlog
        oldest = max(1, head - n + 1)
        parts = []
        if last is None:
            last = oldest - 1
        elif last > head:
            parts.append(_event("reset", {"last": last, "head": head}))
            last = oldest - 1
        first = max(last + 1, oldest)
        if first > last + 1:
            parts.append(_event("dropped", {"dropped": first - last - 1, "from": last + 1, "to": first - 1}))
            last = first - 1
        ring, enc = self._ring, self._enc
        for s in range(first, min(head, first + limit - 1) + 1):
            i = s % n
            sample = ring[i]
            if sample is None or sample["seq"] != s:
                break  # lapped while reading: the next call reports the loss
            cached = enc[i]
            if cached is None or cached[0] != s:
                cached = enc[i] = (s, encode_sample(sample))
            parts.append(cached[1])
            last = s
        return b"".join(parts), last


class _Handler(BaseHTTPRequestHandler):
    server_version = "tactile-host-live"
    protocol_version = "HTTP/1.0"  # one response per connection; the event stream ends when either side closes

    def setup(self):
        # one timeout for reading the request and for every write: a peer that stalls costs its own thread only
        self.timeout = self.server.live.write_timeout
        super().setup()

    def log_message(self, format, *args):  # the command prints its own lines; no access log on stderr
        pass

    def do_HEAD(self):  # what GET would answer, without the body (curl -I, link checkers)
        self._head = True
        self.do_GET()

    def do_GET(self):
        live = self.server.live
        url = urlsplit(self.path)
        path = url.path
        if path in ("/", "/index.html"):
            self._static("live.html")
        elif path.startswith("/static/"):
            self._static(path[len("/static/"):])
        elif path == "/meta":
            self._send(HTTPStatus.OK, "application/json", live.hub.meta_json)
        elif path == "/events":
            self._events(url.query)
        else:
            self._send(HTTPStatus.NOT_FOUND, "text/plain; charset=utf-8", b"not found\n")

    def _send(self, status, ctype: str, body: bytes):
        self.send_response(status)
        self.send_header("Content-Type", ctype)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-cache")
        self.send_header("X-Content-Type-Options", "nosniff")
        self.end_headers()
        if not getattr(self, "_head", False):
            self.wfile.write(body)

    def _static(self, name: str):
        asset = self.server.live.assets.get(name) if _NAME.match(name) else None
        if asset is None:
            self._send(HTTPStatus.NOT_FOUND, "text/plain; charset=utf-8", b"not found\n")
        else:
            self._send(HTTPStatus.OK, *asset)

    def _start(self, query: str) -> int | None:
        """The last sample the viewer has: Last-Event-ID (a reconnect), else ?since=N, else None (all held)."""
        header = self.headers.get("Last-Event-ID", "").strip()
        if header.isdigit():
            return int(header)
        since = parse_qs(query).get("since")
        if since:
            if not since[-1].isdigit():
                raise ValueError(f"since={since[-1]!r} is not a sample number")
            return int(since[-1])
        return None

    def _events(self, query: str):
        live = self.server.live
        try:
            last = self._start(query)
        except ValueError as exc:
            self._send(HTTPStatus.BAD_REQUEST, "text/plain; charset=utf-8", f"{exc}\n".encode())
            return
        if not live.admit(self.connection):
            self._send(HTTPStatus.SERVICE_UNAVAILABLE, "text/plain; charset=utf-8",
                       f"too many viewers (at most {live.max_clients})\n".encode())
            return
        try:
            self.send_response(HTTPStatus.OK)
            self.send_header("Content-Type", "text/event-stream")
            self.send_header("Cache-Control", "no-cache")
            self.end_headers()
            if getattr(self, "_head", False):
                return
            write, hub, stopping = self.wfile.write, live.hub, live.stopping
            # reconnect after 1 s, not the browser's default 3 s; hello: which hub, how far it is
            head = hub.seq
            write(b"retry: 1000\n\n" + _event("hello", {"hub": hub.token, "head": head, "backlog": hub.backlog,
                                                         "resume": last}))
            if last is None:  # a new viewer gets what the ring held at hello; later losses it is told of
                last = max(0, head - hub.backlog)
            quiet_until = time.monotonic() + live.keepalive
            while not stopping.is_set():
                chunk, last = hub.collect(last)
                if chunk:
                    write(chunk)
                    quiet_until = time.monotonic() + live.keepalive
                    if hub.seq - last >= LIMIT:
                        continue  # catching up, in pieces of LIMIT samples; otherwise one write per poll
                elif live.finishing.is_set() and last >= hub.seq:
                    break  # the run has ended and this viewer has every sample of it
                if time.monotonic() >= quiet_until:
                    write(b": keep-alive\n\n")  # lets the page, and proxies, see the stream is alive
                    quiet_until = time.monotonic() + live.keepalive
                stopping.wait(live.poll)
        except OSError:  # closed, reset or timed out: this viewer is gone, the readout goes on
            pass
        finally:
            live.release(self.connection)


class _Server(ThreadingHTTPServer):
    daemon_threads = True

    def server_bind(self):
        # HTTPServer.server_bind asks for the host's FQDN, a DNS lookup that can hang on a Pi with no network
        socketserver.TCPServer.server_bind(self)
        self.server_name, self.server_port = str(self.server_address[0]), self.server_address[1]

    def handle_error(self, request, client_address):  # a viewer's broken connection is not an error to print
        pass


class _Server6(_Server):
    address_family = socket.AF_INET6


def _load_assets() -> dict[str, tuple[str, bytes]]:
    """Every file in ``host/static`` (read once at start: they are small) as name -> (content type, bytes)."""
    out = {}
    for entry in resources.files("host").joinpath("static").iterdir():
        suffix = "." + entry.name.rsplit(".", 1)[-1] if "." in entry.name else ""
        if entry.is_file() and _NAME.match(entry.name):
            out[entry.name] = (STATIC_TYPES.get(suffix, "application/octet-stream"), entry.read_bytes())
    if "live.html" not in out:
        raise InputError("the live view's page is missing from the package (host/static/live.html): reinstall it")
    return out


class LiveServer:
    """The page, its assets, ``/meta`` and ``/events`` for a ``LiveHub``, on ``host``:``port`` (0: any free port).

    Binds at construction, so a port in use or an address this machine lacks is an
    ``InputError`` before the readout starts (``hub`` may be set after, before :meth:`start`).
    ``write_timeout`` (s): a viewer that accepts nothing for that long is dropped; ``keepalive``
    (s): comment lines on an idle stream; ``poll`` (s): how often a viewer's thread looks for
    new samples (each look sends all that is new in one write); ``max_clients``: event streams
    served at once.
    """

    def __init__(self, hub: LiveHub | None, host: str = "127.0.0.1", port: int = 8765, *, write_timeout: float = 10.0,
                 keepalive: float = 5.0, poll: float = 0.02, max_clients: int = 32):
        if not host:
            raise InputError("--host is empty: give an address such as 127.0.0.1 (this machine) or 0.0.0.0 "
                             "(the network)")
        if not isinstance(port, int) or not 0 <= port <= 65535:
            raise InputError(f"--port must be a whole number from 0 to 65535, got {port!r}")
        self.hub, self.write_timeout, self.keepalive, self.poll = hub, write_timeout, keepalive, poll
        self.max_clients = max_clients
        self.assets = _load_assets()
        self.stopping = threading.Event()
        self.finishing = threading.Event()  # the run has ended: streams close once they have sent all of it
        self._clients: set = set()
        self._clients_lock = threading.Lock()
        self._thread = None
        cls = _Server6 if ":" in host else _Server
        try:
            self._httpd = cls((host, port), _Handler)
        except socket.gaierror:
            raise InputError(f"--host {host!r}: not an address or a name this machine can resolve") from None
        except OSError as exc:
            if exc.errno == errno.EADDRINUSE:
                raise InputError(f"port {port} on {host} is in use (another tactile-host view?): choose another "
                                 "with --port") from None
            if exc.errno == errno.EADDRNOTAVAIL:
                raise InputError(f"--host {host}: no interface of this machine has that address") from None
            if exc.errno == errno.EACCES:
                raise InputError(f"port {port}: not allowed for this user (ports below 1024 need root); "
                                 "choose another with --port") from None
            raise InputError(f"cannot serve on {host}:{port}: {exc.strerror or exc}") from None
        self._httpd.live = self

    @property
    def url(self) -> str:
        host, port = self._httpd.server_address[:2]
        if host in ("0.0.0.0", "::"):
            host = "127.0.0.1" if host == "0.0.0.0" else "::1"  # reachable here; other machines use this one's address
        return f"http://[{host}]:{port}/" if ":" in host else f"http://{host}:{port}/"

    @property
    def every_interface(self) -> bool:
        """It listens on every interface (--host 0.0.0.0 or ::): other machines reach it too."""
        return self._httpd.server_address[0] in ("0.0.0.0", "::")

    @property
    def clients(self) -> int:
        """Event streams open now."""
        return len(self._clients)

    def admit(self, conn) -> bool:
        with self._clients_lock:
            if len(self._clients) >= self.max_clients:
                return False
            self._clients.add(conn)
            return True

    def release(self, conn) -> None:
        with self._clients_lock:
            self._clients.discard(conn)

    def start(self) -> None:
        """Serve in a daemon thread (each connection in its own daemon thread); the hub must be set by now."""
        if self.hub is None:
            raise ValueError("LiveServer.start: no hub to serve")
        if self._thread is None:
            self._thread = threading.Thread(target=self._httpd.serve_forever, kwargs={"poll_interval": 0.2},
                                            name="live-server", daemon=True)
            self._thread.start()

    def stop(self, drain: float = 0.0) -> None:
        """Close every stream and the listening socket; returns within about a poll interval. ``drain`` (s): first
        let each stream send the samples it has not yet (the end of a run that ended), for up to that long."""
        self.finishing.set()
        deadline = time.monotonic() + drain
        while self.clients and time.monotonic() < deadline:
            time.sleep(self.poll)
        self.stopping.set()
        with self._clients_lock:
            conns = list(self._clients)
        for conn in conns:  # wakes a writer blocked on a stalled viewer now instead of at its timeout
            try:
                conn.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
        if self._thread is not None:
            self._httpd.shutdown()
            self._thread.join()
            self._thread = None
        self._httpd.server_close()

    def __enter__(self):
        self.start()
        return self

    def __exit__(self, *exc):
        self.stop()
