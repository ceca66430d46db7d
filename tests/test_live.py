"""The live view: the hub and server over plain HTTP (ordering, reconnects, slow viewers, assets, errors), then the
page itself in headless Chromium against ``tactile-host view --simulate motion`` and against a restarted server.

``TM_LIVE_PNG=docs/img/live.png python -m pytest tests/test_live.py -k tactile_host_view`` regenerates the
screenshot docs/live.md shows.
"""

from __future__ import annotations

import http.client
import json
import math
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from conftest import IN_CI, TWO_CHIPS, assert_one_line_error, require_tool, run_cli
from fitgen.base.errors import InputError
from host.live import LiveHub, LiveServer

META = {"inputs": [f"v{k}" for k in range(1, 9)], "input_units": "V", "outputs": ["dx", "dy", "dz", "thx", "thy"],
        "units": ["mm", "mm", "mm", "deg", "deg"], "model": "0123456789ab", "source": "test publisher", "rate": None}


def sample(i: int) -> dict:
    """The i-th published sample (0-based); ``out.dx`` = i, so a receiver can check it got the right one."""
    return {"t": 1.7e9 + i * 1e-3, "v": [1.5 + 1e-4 * k for k in range(8)], "raw": [1.5] * 8,
            "out": {"dx": float(i), "dy": 0.5, "dz": -1.0, "thx": 1.0, "thy": -2.0}, "status": 0, "temp": None,
            "rate": 1000.0, "errors": {"total": 0, "nack": 0, "timeout": 0, "stuck": 0, "other": 0, "retries": 0,
                                       "resets": 0}, "zero": {"updates": 0, "last": None}}


def wait_until(cond, timeout: float = 20.0, what: str = "condition"):
    end = time.monotonic() + timeout
    while not cond():
        if time.monotonic() > end:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.01)


class SSE:
    """A minimal EventSource over http.client: ``next()`` is the next event as {event, id, data}."""

    def __init__(self, srv: LiveServer, path: str = "/events", last_id: int | None = None, timeout: float = 20.0):
        host, port = srv._httpd.server_address[:2]
        self.conn = http.client.HTTPConnection(host, port, timeout=timeout)
        self.conn.request("GET", path, headers={} if last_id is None else {"Last-Event-ID": str(last_id)})
        self.resp = self.conn.getresponse()
        assert self.resp.status == 200, self.resp.status
        assert self.resp.getheader("Content-Type") == "text/event-stream"

    def next(self) -> dict:
        ev = {"event": "message", "id": None, "data": []}
        while True:
            line = self.resp.readline()
            if not line:
                raise EOFError("the server closed the stream")
            line = line.decode().rstrip("\n")
            if not line:
                if ev["data"]:
                    return {**ev, "data": json.loads("\n".join(ev["data"]))}
                ev = {"event": "message", "id": None, "data": []}
            elif line.startswith(":"):
                continue  # keep-alive
            else:
                key, _, value = line.partition(":")
                value = value[1:] if value.startswith(" ") else value
                if key == "data":
                    ev["data"].append(value)
                elif key in ("event", "id"):
                    ev[key] = value

    def until(self, seq: int) -> list[dict]:
        """Every event up to and including the sample ``seq``."""
        out = []
        while True:
            ev = self.next()
            out.append(ev)
            if ev["event"] == "message" and ev["data"]["seq"] >= seq:
                return out

    def close(self):
        self.conn.close()


def seqs(events) -> list[int]:
    return [e["data"]["seq"] for e in events if e["event"] == "message"]


def check_ids(events):
    """Each sample event's id is its seq, and its content is the one published with that seq."""
    for e in events:
        if e["event"] == "message":
            assert int(e["id"]) == e["data"]["seq"]
            assert e["data"]["out"]["dx"] == e["data"]["seq"] - 1


class Publisher(threading.Thread):
    """Publishes samples 0..n-1 in batches with pauses, as a readout would (faster)."""

    def __init__(self, hub: LiveHub, n: int, batch: int = 20, pause: float = 0.005, start: int = 0):
        super().__init__(daemon=True)
        self.hub, self.n, self.batch, self.pause, self.first = hub, n, batch, pause, start
        self.halt = threading.Event()

    def run(self):
        for i in range(self.first, self.n):
            if self.halt.is_set():
                return
            self.hub.publish(sample(i))
            if i % self.batch == self.batch - 1:
                time.sleep(self.pause)


@pytest.fixture
def served():
    servers = []

    def make(backlog: int = 4096, **kw):
        hub = LiveHub(META, backlog=backlog)
        srv = LiveServer(hub, "127.0.0.1", 0, **kw)
        srv.start()
        servers.append(srv)
        return hub, srv

    yield make
    for srv in servers:
        srv.stop()


def raw_get(srv: LiveServer, path: str, method: str = "GET") -> tuple[int, dict, bytes]:
    """GET with the path sent byte for byte (http.client and browsers would normalise '..')."""
    host, port = srv._httpd.server_address[:2]
    with socket.create_connection((host, port), timeout=10) as s:
        s.sendall(f"{method} {path} HTTP/1.0\r\nHost: x\r\n\r\n".encode())
        data = b""
        while chunk := s.recv(65536):
            data += chunk
    head, _, body = data.partition(b"\r\n\r\n")
    lines = head.decode("latin-1").split("\r\n")
    headers = dict(ln.split(": ", 1) for ln in lines[1:])
    return int(lines[0].split()[1]), headers, body


# --- hub and server, no browser -----------------------------------------------------------------------------


def test_publish_numbers_samples_and_keeps_the_backlog():
    hub = LiveHub(META, backlog=10)
    items = [sample(i) for i in range(25)]
    for s in items:
        hub.publish(s)
    assert [s["seq"] for s in items] == list(range(1, 26)) and hub.seq == 25
    body, last = hub.collect(None)
    assert last == 25 and body.count(b"id: ") == 10  # the 10 newest
    assert body.startswith(b"id: 16\n")
    body, last = hub.collect(25)
    assert (body, last) == (b"", 25)
    with pytest.raises(InputError):
        LiveHub(META, backlog=0)


def test_two_viewers_receive_the_same_consecutive_samples(served):
    hub, srv = served()
    a, b = SSE(srv), SSE(srv)
    wait_until(lambda: srv.clients == 2, what="two viewers")
    got = {}

    def read(name, client):
        got[name] = client.until(3000)

    readers = [threading.Thread(target=read, args=(k, c)) for k, c in (("a", a), ("b", b))]
    for r in readers:
        r.start()
    pub = Publisher(hub, 3000)
    pub.start()
    pub.join(30)
    for r in readers:
        r.join(30)
    for name in "ab":
        events = got[name]
        assert events[0]["event"] == "hello" and events[0]["data"]["hub"] == hub.token
        assert seqs(events) == list(range(1, 3001)), name
        assert not [e for e in events if e["event"] in ("dropped", "reset")]
        check_ids(events)
    a.close(), b.close()


def test_reconnect_with_last_event_id_resumes_without_a_gap(served):
    hub, srv = served(backlog=20000)
    pub = Publisher(hub, 6000, batch=10)  # about 2,000 samples/s, 3 s
    first = SSE(srv)
    pub.start()
    seen = first.until(300)
    n = seqs(seen)[-1]
    first.close()  # the browser goes away ...
    wait_until(lambda: hub.seq >= n + 1000, what="the publisher to go on")  # ... while the readout goes on
    again = SSE(srv, last_id=n)
    events = again.until(6000)
    assert seqs(events) == list(range(n + 1, 6001))
    assert not [e for e in events if e["event"] in ("dropped", "reset")]
    check_ids(events)
    assert seqs(seen) == list(range(1, n + 1))
    # ?since=N is the same for a first connection; a Last-Event-ID header wins over it
    since = SSE(srv, path=f"/events?since={n}").until(n + 5)
    assert seqs(since) == list(range(n + 1, n + 6))
    both = SSE(srv, path="/events?since=7", last_id=n).until(n + 1)
    assert seqs(both) == [n + 1]
    pub.join(30)


def test_a_viewer_behind_the_backlog_is_told_what_it_lost(served):
    hub, srv = served(backlog=100)
    for i in range(500):
        hub.publish(sample(i))
    events = SSE(srv, path="/events?since=10").until(500)
    assert [e["event"] for e in events[:2]] == ["hello", "dropped"]
    assert events[1]["data"] == {"dropped": 390, "from": 11, "to": 400}
    assert events[1]["id"] is None  # so that the browser's Last-Event-ID stays the last sample's
    assert seqs(events) == list(range(401, 501))
    # a page that has more than this hub ever published (the readout was restarted) starts again
    events = SSE(srv, last_id=9999).until(500)
    assert [e["event"] for e in events[:2]] == ["hello", "reset"] and seqs(events) == list(range(401, 501))
    # a first connection gets what the hub holds, with no loss to report
    events = SSE(srv).until(500)
    assert [e["event"] for e in events[:2]] == ["hello", "message"] and seqs(events) == list(range(401, 501))
    status, _, body = raw_get(srv, "/events?since=-3")
    assert status == 400 and b"not a sample number" in body


def test_a_new_viewer_is_told_of_samples_the_ring_lost_after_it_connected(served):
    """A new viewer gets what the ring held when it was greeted; a viewer whose thread first looks after the ring
    has lapped (a loaded machine) is told of the samples lost since, not given the ring's oldest silently."""
    hub, srv = served(backlog=16)
    first_look, go = threading.Event(), threading.Event()
    collect = hub.collect

    def late_collect(last, *a, **kw):
        if not first_look.is_set():
            first_look.set()
            go.wait(10)  # the readout publishes meanwhile
        return collect(last, *a, **kw)

    hub.collect = late_collect
    reader = SSE(srv)
    assert reader.next()["event"] == "hello"
    assert first_look.wait(10)
    for i in range(100):
        hub.publish(sample(i))
    go.set()
    got = [reader.next(), reader.next()]
    assert got[0]["event"] == "dropped" and got[0]["data"] == {"dropped": 84, "from": 1, "to": 84}, got
    assert got[1]["event"] == "message" and got[1]["data"]["seq"] == 85
    reader.close()


def test_a_stalled_viewer_does_not_slow_publish_and_is_dropped(served):
    hub, srv = served(write_timeout=3.0)
    host, port = srv._httpd.server_address[:2]
    stalled = socket.socket()
    stalled.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)  # a small window: its buffers fill soon
    stalled.connect((host, port))
    stalled.sendall(b"GET /events HTTP/1.0\r\n\r\n")  # ... and never reads
    reader = SSE(srv)
    wait_until(lambda: srv.clients == 2, what="both viewers")
    got = []
    stop = threading.Event()

    def read():
        while not stop.is_set():
            try:
                got.append(reader.next())
            except (EOFError, OSError):
                return

    t = threading.Thread(target=read, daemon=True)
    t.start()
    worst, t0 = 0.0, time.perf_counter()
    for i in range(50_000):
        a = time.perf_counter()
        hub.publish(sample(i))
        worst = max(worst, time.perf_counter() - a)
    elapsed = time.perf_counter() - t0
    # a publish that waited for the stalled viewer would take the write timeout (3 s)
    assert worst < 1.0 and elapsed < 15.0, (worst, elapsed)
    # keep the readout going until the stalled viewer's write times out: only its own thread waited
    i = 50_000
    deadline = time.monotonic() + 30
    while srv.clients > 1 and time.monotonic() < deadline:
        for _ in range(500):
            hub.publish(sample(i))
            i += 1
        time.sleep(0.01)
    assert srv.clients == 1, "the stalled viewer was not dropped"
    # the reading viewer got the newest sample (and was told of any it lost while the test published flat out)
    wait_until(lambda: got and got[-1]["event"] == "message" and got[-1]["data"]["seq"] == hub.seq,
               what="the reader to reach the newest sample")
    stop.set()
    lost = sum(e["data"]["dropped"] for e in got if e["event"] == "dropped")
    assert len(seqs(got)) + lost == hub.seq
    stalled.close()
    reader.close()


def test_assets_are_served_and_nothing_escapes_the_static_folder(served):
    hub, srv = served()
    status, headers, page = raw_get(srv, "/")
    assert status == 200 and headers["Content-Type"].startswith("text/html")
    refs = re.findall(rb'(?:src|href)="([^"]+)"', page)
    assert refs and all(r.startswith(b"/static/") for r in refs), refs  # everything from here: no CDN
    for ref in refs:
        status, headers, body = raw_get(srv, ref.decode())
        assert status == 200 and body, ref
        assert not re.search(rb"https?://", body), ref  # nor a URL inside an asset
    assert raw_get(srv, "/static/live.js")[1]["Content-Type"].startswith("text/javascript")
    for path in ("/static/../live.py", "/static/..%2Flive.py", "/static/%2e%2e/live.py", "/static/../../README.md",
                 "/static//etc/passwd", "/static/", "/static/..", "/static/.hidden", "/../host/live.py",
                 "/static/live.js/../../live.py", "/nothing"):
        status, _, body = raw_get(srv, path)
        assert status == 404, path
        assert b"LiveHub" not in body
    meta = json.loads(raw_get(srv, "/meta")[2])
    assert meta == META


def test_head_answers_as_get_without_a_body(served):
    hub, srv = served()
    hub.publish(sample(0))
    for path in ("/", "/static/live.js", "/meta", "/nothing"):
        status, headers, body = raw_get(srv, path)
        h_status, h_headers, h_body = raw_get(srv, path, "HEAD")
        assert (h_status, h_headers["Content-Type"], h_body) == (status, headers["Content-Type"], b""), path
        assert int(h_headers["Content-Length"]) == len(body), path
    status, headers, body = raw_get(srv, "/events", "HEAD")  # the stream's headers, then the end: no events
    assert (status, headers["Content-Type"], body) == (200, "text/event-stream", b"")


def test_non_finite_values_reach_the_page_as_null(served):
    import numpy as np

    hub, srv = served()
    s = sample(0)
    s.update(v=np.array([math.nan] + [1.0] * 7), status=-1, temp=np.float32(21.5),
             out={"dx": math.inf, "dy": 0.0, "dz": np.float64(-1.0), "thx": math.nan, "thy": 0.0})
    hub.publish(s)
    ev = SSE(srv).until(1)[-1]["data"]
    assert ev["v"][:2] == [None, 1.0] and ev["out"]["dx"] is None and ev["out"]["thx"] is None
    assert ev["out"]["dz"] == -1.0 and ev["temp"] == 21.5 and ev["status"] == -1


def test_stop_ends_the_streams(served):
    hub, srv = served()
    client = SSE(srv)
    assert client.next()["event"] == "hello"
    t0 = time.monotonic()
    srv.stop()
    with pytest.raises((EOFError, OSError)):
        while True:
            client.next()
    assert time.monotonic() - t0 < 5
    hub.publish(sample(0))  # the readout goes on without a server


def test_a_port_in_use_or_a_bad_address_is_one_sentence(served, model_file):
    hub, srv = served()
    port = srv._httpd.server_address[1]
    assert srv.url == f"http://127.0.0.1:{port}/"
    for host, port_, needle in (("127.0.0.1", port, f"port {port} on 127.0.0.1 is in use"),
                                ("no-such-host.invalid", 0, "no-such-host.invalid"),
                                ("192.0.2.7", 0, "no interface"),  # TEST-NET-1: never this machine's
                                ("", 0, "--host is empty"),
                                ("127.0.0.1", 70000, "65535")):
        with pytest.raises(InputError) as err:
            LiveServer(hub, host, port_)
        msg = str(err.value)
        assert needle in msg and "\n" not in msg and msg.count(". ") == 0, msg
    proc = run_cli("tactile-host", "view", "--model", model_file, "--adc", TWO_CHIPS, "--simulate", "dx=1",
                   "--port", str(port), "--duration", "1")
    assert_one_line_error(proc, 2, f"port {port}")


def test_a_run_that_ends_reaches_its_viewer_whole(model_file):
    """`view --count N`: a viewer connected during the run gets all N samples, the last included, and then the
    end of the stream (the server used to stop before the last poll sent it)."""
    code = "import sys; from fitgen.app.host_cli import main; sys.argv[0] = 'tactile-host'; main()"
    proc = subprocess.Popen([sys.executable, "-c", code, "view", "--model", model_file, "--adc", TWO_CHIPS,
                             "--simulate", "motion", "--port", "0", "--rate", "50", "--count", "100"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        match = re.search(r"http://127\.0\.0\.1:(\d+)/", proc.stderr.readline())
        assert match
        ids = []
        with socket.create_connection(("127.0.0.1", int(match.group(1))), timeout=30) as s:
            s.sendall(b"GET /events?since=0 HTTP/1.0\r\nHost: x\r\n\r\n")
            data = b""
            while chunk := s.recv(65536):  # to the stream's end
                data += chunk
        ids = [int(x) for x in re.findall(rb"^id: (\d+)$", data, flags=re.M)]
        assert ids == list(range(1, 101)), ids[-3:]
    finally:
        _, err = proc.communicate(timeout=30)
    assert proc.returncode == 0 and "done: 100 samples" in err, err


def test_view_on_every_interface_says_the_network_can_see_it(model_file):
    """--host 0.0.0.0 listens beyond this machine: the serving line says so (the URL it prints is this
    machine's), and on 127.0.0.1 it says only the URL."""
    for host, wide in (("0.0.0.0", True), ("127.0.0.1", False)):
        proc = run_cli("tactile-host", "view", "--model", model_file, "--adc", TWO_CHIPS, "--simulate", "dx=1",
                       "--host", host, "--port", "0", "--count", "2")
        assert proc.returncode == 0, proc.stderr
        first = proc.stderr.splitlines()[0]
        assert re.match(r"tactile-host view: serving http://127\.0\.0\.1:\d+/ ", first), first
        assert ("and on every interface (from another machine: this one's address, the same port; anyone on the "
                "network can see it)" in first) == wide, first


def test_the_page_ships_with_the_package():
    from importlib import resources

    try:
        import tomllib
    except ImportError:  # Python 3.10
        import tomli as tomllib

    conf = tomllib.loads((Path(__file__).parents[1] / "pyproject.toml").read_text())
    assert "static/*" in conf["tool"]["setuptools"]["package-data"]["host"]
    names = {p.name for p in resources.files("host").joinpath("static").iterdir()}
    assert {"live.html", "live.js", "live.css"} <= names


# --- the page in a headless browser ---------------------------------------------------------------------------


@pytest.fixture
def browser():
    chromium = require_tool("chromium")
    driver_path = require_tool("chromedriver")
    try:
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service
    except ImportError:
        msg = "selenium is not installed (pip install -e '.[live-test]'; scripts/test installs it)"
        pytest.fail(msg) if IN_CI else pytest.skip(msg)
    opts = webdriver.ChromeOptions()
    opts.binary_location = chromium
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                "--window-size=1400,900", "--hide-scrollbars", "--force-device-scale-factor=1"):
        opts.add_argument(arg)
    drv = webdriver.Chrome(options=opts, service=Service(executable_path=driver_path))
    drv.set_page_load_timeout(30)
    yield drv
    drv.quit()


def text(drv, id_: str) -> str:
    return drv.execute_script("return document.getElementById(arguments[0]).textContent;", id_)


def page_wait(drv, cond, timeout: float = 20.0, what: str = "the page"):
    wait_until(lambda: cond(drv), timeout, what)


def inked(drv, canvas_id: str) -> int:
    """Pixels of a canvas that are drawn in a colour (not white, grey or transparent): the plotted lines."""
    return drv.execute_script("""
        const c = document.getElementById(arguments[0]);
        const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
        let n = 0;
        for (let i = 0; i < d.length; i += 4) {
          const r = d[i], g = d[i + 1], b = d[i + 2];
          if (d[i + 3] > 0 && Math.max(r, g, b) - Math.min(r, g, b) > 60) n++;
        }
        return n;""", canvas_id)


def test_page_follows_tactile_host_view(browser, device_model, tmp_path):
    docs_png = os.environ.get("TM_LIVE_PNG")
    model_file = str(device_model.save(tmp_path / "model.json"))  # fitted as `fitgen fit` does by default
    code = "import sys; from fitgen.app.host_cli import main; sys.argv[0] = 'tactile-host'; main()"
    proc = subprocess.Popen([sys.executable, "-c", code, "view", "--model", model_file, "--adc", TWO_CHIPS,
                             "--simulate", "motion", "--port", "0", "--duration", "90"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        line = proc.stderr.readline()  # the command says where it serves before it reads the first sample
        match = re.search(r"http://\S+/", line)
        assert match, line + (proc.stderr.read() if proc.poll() is not None else "")
        browser.get(match.group(0))
        page_wait(browser, lambda d: text(d, "conn") == "live" and int(text(d, "count")) > 20, what="samples")
        dx0, n0 = text(browser, "dx"), int(text(browser, "count"))
        time.sleep(1.5)
        page_wait(browser, lambda d: int(text(d, "count")) > n0 and text(d, "dx") != dx0, 10, "new values")
        dx1 = float(text(browser, "dx"))
        assert abs(dx1) < 5 and text(browser, "conn") == "live"
        assert re.fullmatch(r"-?\d+\.\d{3}", text(browser, "dz")) and text(browser, "domain")
        assert float(text(browser, "rate")) > 0
        assert text(browser, "source").startswith("simulated")
        for canvas in ("topview", "plot-disp", "plot-tilt", "plot-elem"):
            assert inked(browser, canvas) > 200, canvas
        if docs_png:  # for the picture: 10 s of plots, taken while the simulated finger presses
            time.sleep(8)
            page_wait(browser, lambda d: float(text(d, "dz")) < -0.7, 30, "a press")
        shot = tmp_path / "live.png"
        assert browser.save_screenshot(str(shot)) and shot.stat().st_size > 10_000
        if docs_png:
            tmp = Path(docs_png).with_suffix(".png.tmp")
            shutil.copyfile(shot, tmp)
            os.replace(tmp, docs_png)
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            _, err = proc.communicate(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()
            _, err = proc.communicate()
    assert proc.returncode == 0 and "Traceback" not in err, err
    assert "stopped" in err


def test_page_says_when_the_estimate_lies_far_outside_the_fitted_box(browser, served):
    """Every reading inside its range (status 0) and the estimate far outside the model's fitted pose box (the
    drawing's model on a built unit): the domain cell says so, as a warning; a sample back inside clears it."""
    hub, srv = served()
    hub.publish({**sample(0), "far": True})
    browser.get(srv.url)
    page_wait(browser, lambda d: int(text(d, "count")) == 1, what="the sample")
    dom = browser.find_element("id", "domain")
    assert dom.text == "inside; estimate far outside the fitted pose box: another sensor than the model's?"
    assert dom.get_attribute("class") == "warn"
    hub.publish({**sample(1), "far": False})
    page_wait(browser, lambda d: text(d, "domain") == "inside", what="the domain cleared")
    assert browser.find_element("id", "domain").get_attribute("class") == "ok"
    # from a read held up between its conversions: readings of two poses, not another sensor's
    hub.publish({**sample(2), "far": True, "held": True})
    page_wait(browser, lambda d: text(d, "domain") == "inside; estimate far outside the fitted pose box from a read "
              "held up between its conversions", what="the held-up read")
    assert browser.find_element("id", "domain").get_attribute("class") == "warn"


def test_page_reconnects_and_loses_nothing(browser, served):
    hub, srv = served(backlog=1 << 17)  # the gap lasts seconds on a loaded machine: the ring must outlast it
    port = srv._httpd.server_address[1]
    browser.get(srv.url)
    page_wait(browser, lambda d: text(d, "conn") == "live", what="the stream")
    pub = Publisher(hub, 10**9, batch=5, pause=0.005)  # about 1,000 samples/s until halted
    pub.start()
    again = None
    try:
        page_wait(browser, lambda d: int(text(d, "count")) > 300, what="samples")
        srv.stop()  # the server goes away; the readout (the publisher) goes on
        page_wait(browser, lambda d: text(d, "conn") == "reconnecting", 10, "the page to notice")
        time.sleep(0.5)
        again = LiveServer(hub, "127.0.0.1", port)  # back on the same port with the same hub
        again.start()
        page_wait(browser, lambda d: text(d, "conn") == "live", 15, "the page to reconnect")
        time.sleep(0.5)
        pub.halt.set()
        pub.join(10)
        # every sample the hub published reached the page exactly once: none lost in the gap, none twice
        page_wait(browser, lambda d: int(text(d, "count")) == hub.seq, 15, f"count == {hub.seq}")
        assert text(browser, "dropped") == "0"
        assert float(text(browser, "dx")) == hub.seq - 1
    finally:
        pub.halt.set()
        if again is not None:
            again.stop()


def test_page_follows_a_restarted_readout_from_its_first_sample(browser, served):
    hub, srv = served()
    for i in range(300):
        hub.publish(sample(i))
    port = srv._httpd.server_address[1]
    browser.get(srv.url)
    page_wait(browser, lambda d: int(text(d, "count")) == 300, what="the first readout's samples")
    srv.stop()
    page_wait(browser, lambda d: text(d, "conn") == "reconnecting", 10, "the page to notice")
    # the new readout is further on than the page's Last-Event-ID (300): resuming by it would skip 300 samples
    again = LiveHub(META)
    for i in range(1000):
        again.publish(sample(i))
    new = LiveServer(again, "127.0.0.1", port)
    new.start()
    try:
        page_wait(browser, lambda d: int(text(d, "count")) == 1300, 15, "every sample of the new readout")
        assert text(browser, "note") == "the readout was restarted" and text(browser, "conn") == "live"
        assert float(text(browser, "dx")) == 999
    finally:
        new.stop()


def test_page_reloads_for_a_restarted_readout_with_other_outputs(browser, served):
    hub, srv = served()
    hub.publish(sample(0))
    port = srv._httpd.server_address[1]
    browser.get(srv.url)
    page_wait(browser, lambda d: int(text(d, "count")) == 1, what="a sample")
    srv.stop()
    page_wait(browser, lambda d: text(d, "conn") == "reconnecting", 10, "the page to notice")
    again = LiveHub({**META, "outputs": ["dz"], "units": ["mm"]})
    for i in range(5):
        again.publish(sample(i))
    new = LiveServer(again, "127.0.0.1", port)
    new.start()
    try:
        page_wait(browser, lambda d: d.execute_script("return document.getElementById('dx') === null;")
                  and text(d, "count") == "5", 15, "the page rebuilt for dz alone")
        assert text(browser, "dz") and text(browser, "conn") == "live"
    finally:
        new.stop()
