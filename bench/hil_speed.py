"""How fast the emulated firmware answers (issue 20, parts 4 and 5): the first STREAM after boot with ADCs over
the I2C bridge, and the whole HIL suite on the emulated Cortex-M4, for this tree and a baseline revision side
by side in one run.

    python bench/hil_speed.py --baseline 57aa95d > /tmp/hil_speed.md

Each code version runs from its own files: the baseline is `git archive`d into a temporary folder and run
with that folder first on PYTHONPATH (its CLI, its firmware sources, its serial client). Its CLI is the
`tactile-hil` entry point of its own pyproject.toml (hil.cli at 57aa95d, fitgen.app.hil_cli since the
layers), its fit the modules it has (fitgen.fit or fitgen.fitting.fit, ...), and an editable install of
this tree is kept from filling in the modules the baseline lacks. Runs alternate between the versions, so
that the load of a shared machine falls on both alike; the table gives medians.

Needs qemu-system-arm and arm-none-eabi-gcc (apt: qemu-system-arm gcc-arm-none-eabi libnewlib-arm-none-eabi)
for mps2 and the suite, gcc for the host target; checked before anything runs. A quick check of both sides:
`python bench/hil_speed.py --boots 1 --suites 0 --targets host` (about 10 s).

- first STREAM: `tactile-hil emulate --target T --adc ads1115@0x48:0-3,ads1115@0x49:0-3 --simulate
  dx=1,dz=-1` is started; once it prints `ready`, a client (the version's own host.device) connects and
  sends STREAM (5 samples, 10 ms), the user's first command. Figures: launch to `ready`; request to the
  first and to the fifth sample; launch to the first sample.
- HIL suite: `tactile-hil emulate --model paper.json --suite` on mps2 (float, table; 1,000 vectors,
  10,000 fuzz frames). Figures: the fuzz check, the suite (the sum of its checks, as each version prints
  them), and the whole command (build, boot, instruction count, suite).
"""

from __future__ import annotations

import os
import re
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchutil import log, need_tools, parser, table
from fitgen.base.texts import tomllib
from hil.emulate import stop_process

ROOT = Path(__file__).resolve().parent.parent
ADC = "ads1115@0x48:0-3,ads1115@0x49:0-3"
POSE = "dx=1,dz=-1"
# The first line of every program a version runs: setuptools' editable install of this tree puts a finder on
# sys.meta_path that answers any module the baseline's folder lacks (fitgen.app.hil_cli, fitgen.fitting, ...)
# with this tree's file, so that the baseline would run a mix of the two versions; without it, a version's
# imports find its own files (cwd and PYTHONPATH) and the installed dependencies only.
ISOLATE = ("import sys; sys.meta_path[:] = [f for f in sys.meta_path "
           "if not getattr(f, '__module__', '').startswith('__editable__')]\n")

# where the modules FIT imports were before the layers (676fefc): a version without the new file imports the old
MOVED = {"fitgen.fitting.fit": "fitgen.fit", "fitgen.physics.sensor": "fitgen.sensor",
         "fitgen.physics.simulate": "fitgen.simulate"}

# fits the two models with the version's own code (its model file format): paper (suite), volts (ADC builds)
FIT = """
import sys
from fitgen.fitting.fit import FitSettings, fit_model
from fitgen.physics.sensor import load_sensor
from fitgen.physics.simulate import PAPER_GRIDS, grid_poses, simulate
fit_model(simulate(load_sensor("paper"), grid_poses(PAPER_GRIDS["paper-sim"]))).save(sys.argv[1])
grid = grid_poses({"dx": [-2, -1, 0, 1, 2], "dy": [-2, -1, 0, 1, 2], "dz": [0, -1, -2], "thx": [-5, 0, 5],
                   "thy": [-5, 0, 5]})
fit_model(simulate(load_sensor("paper").with_transfer("gmr"), grid), settings=FitSettings()).save(sys.argv[2])
"""

# the user's first command: STREAM 5 samples at 10 ms; prints the arrival of each after the request (s)
CLIENT = """
import sys, time
from host import protocol as P
from host.device import Device
with Device.open(sys.argv[1], timeout=float(sys.argv[2])) as dev:
    info = dev.info()
    seq = dev._seq % 255 + 1
    t0 = time.perf_counter()
    dev.request(P.MsgType.STREAM, P.pack_stream(10, 5))
    arrivals = []
    while len(arrivals) < 5:
        f = dev.receive(max(0.0, t0 + float(sys.argv[2]) - time.perf_counter()))
        if f is None:
            sys.exit("no sample")
        if f.type == P.MsgType.STREAM_SAMPLE and f.seq == seq:
            arrivals.append(time.perf_counter() - t0)
print(" ".join(f"{a:.4f}" for a in arrivals))
"""


def entry_point(root: Path, script: str) -> str:
    """Code that runs ``script`` as the version at ``root`` installs it (its pyproject.toml's [project.scripts]):
    the module moved between versions (hil.cli at 57aa95d, fitgen.app.hil_cli later)."""
    with open(root / "pyproject.toml", "rb") as f:
        module, _, func = tomllib.load(f)["project"]["scripts"][script].partition(":")
    return f"import sys; from {module} import {func}; sys.argv[0] = {script!r}; {func}()"


class Version:
    def __init__(self, name: str, root: Path, models: Path):
        self.name, self.root, self.models = name, root, models
        self.env = dict(os.environ, PYTHONPATH=f"{root}{os.pathsep}{os.environ.get('PYTHONPATH', '')}")
        self.cli = entry_point(root, "tactile-hil")
        self.fit_code = FIT
        for new, old in MOVED.items():
            if not (root / (new.replace(".", "/") + ".py")).is_file():
                self.fit_code = self.fit_code.replace(f"from {new} import", f"from {old} import")

    def python(self, code: str, *args: str, **kw) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "-c", ISOLATE + code, *args], env=self.env, cwd=self.root,
                              text=True, capture_output=True, **kw)

    def fit(self) -> None:
        self.models.mkdir(parents=True, exist_ok=True)
        proc = self.python(self.fit_code, str(self.models / "paper.json"), str(self.models / "volts.json"))
        if proc.returncode:
            sys.exit(f"{self.name}: fitting failed: {proc.stderr.strip().splitlines()[-1:]}")

    def first_stream(self, target: str, limit: float = 120.0) -> dict:
        """Boot emulate --adc, wait for ready, run the client; the times of one boot (s)."""
        t_launch = time.perf_counter()
        proc = subprocess.Popen([sys.executable, "-c", ISOLATE + self.cli, "emulate", "--model",
                                 str(self.models / "volts.json"), "--target", target, "--adc", ADC, "--simulate", POSE],
                                env=self.env, cwd=self.root, text=True, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE)
        try:
            url = None
            for line in proc.stdout:  # "ready: URL (Ctrl-C stops)"; emulate exits on a failure
                m = re.match(r"ready: (\S+)", line)
                if m:
                    url = m.group(1)
                    break
            if url is None:
                sys.exit(f"{self.name} {target}: emulate did not get ready: {proc.stderr.read().strip()}")
            t_ready = time.perf_counter()
            client = self.python(CLIENT, url, str(limit), timeout=limit + 30)
            if client.returncode:
                sys.exit(f"{self.name} {target}: {client.stderr.strip() or client.stdout.strip()}")
            arrivals = [float(x) for x in client.stdout.split()]
        finally:
            stop_process(proc, signal.SIGINT, timeout=20)
        return {"ready": t_ready - t_launch, "first": arrivals[0], "fifth": arrivals[-1],
                "launch_to_first": t_ready - t_launch + arrivals[0]}

    def suite(self) -> dict:
        t0 = time.perf_counter()
        proc = self.python(self.cli, "emulate", "--model", str(self.models / "paper.json"), "--suite", timeout=1800)
        wall = time.perf_counter() - t0
        if proc.returncode:
            sys.exit(f"{self.name}: the HIL suite failed:\n{proc.stdout}\n{proc.stderr}")
        checks = {m.group(1): float(m.group(2))
                  for m in re.finditer(r"^  ([a-z -]+): pass \(([0-9.]+) s\)$", proc.stdout, re.M)}
        return {"fuzz": checks["fuzz"], "suite": sum(checks.values()), "command": wall}


def archive(rev: str, into: Path) -> Path:
    into.mkdir(parents=True)
    git = subprocess.run(["git", "-C", str(ROOT), "archive", rev], capture_output=True)
    if git.returncode:  # a revision git does not know is a bad option: one line and exit 2, not a traceback
        print(f"hil_speed.py: error: --baseline {rev}: {git.stderr.decode().strip().splitlines()[-1]}", file=sys.stderr)
        sys.exit(2)
    subprocess.run(["tar", "-x", "-C", str(into)], input=git.stdout, check=True)
    return into


def main() -> None:
    ap = parser(__doc__)
    ap.add_argument("--baseline", default="57aa95d", help="the revision to compare with (default 57aa95d)")
    ap.add_argument("--boots", type=int, default=5, help="boots per target and version (default 5)")
    ap.add_argument("--suites", type=int, default=3, help="suite runs per version (default 3; 0: none)")
    ap.add_argument("--targets", default="mps2,host", help="targets of the first-STREAM runs (default mps2,host)")
    args = ap.parse_args()
    targets = [t for t in args.targets.split(",") if t]
    if args.boots < 1 or args.suites < 0 or not targets:  # the table needs a boot per target to take medians of
        ap.error("--boots must be >= 1, --suites >= 0 and --targets name a target")
    # the ARM tools for an emulated Cortex-M (and every suite run: mps2), gcc for the host target
    need_tools(*(["qemu-system-arm", "arm-none-eabi-gcc"] if args.suites or set(targets) - {"host"} else []),
               *(["gcc"] if "host" in targets else []))
    with tempfile.TemporaryDirectory(prefix="hil-speed-") as tmp:
        tmp = Path(tmp)
        base = Version(f"baseline {args.baseline}", archive(args.baseline, tmp / "baseline"), tmp / "models-base")
        this = Version("this tree", ROOT, tmp / "models-this")
        versions = (base, this)
        for v in versions:
            log(f"{v.name}: fitting the models")
            v.fit()
        boots = {(v.name, t): [] for v in versions for t in targets}
        for k in range(args.boots):
            for t in targets:
                for v in versions:
                    r = v.first_stream(t)
                    boots[v.name, t].append(r)
                    log(f"boot {k + 1}/{args.boots} {t} {v.name}: ready {r['ready']:.2f} s, first sample "
                        f"{r['first']:.3f} s, fifth {r['fifth']:.3f} s after the request")
        suites = {v.name: [] for v in versions}
        for k in range(args.suites):
            for v in versions:
                r = v.suite()
                suites[v.name].append(r)
                log(f"suite {k + 1}/{args.suites} {v.name}: fuzz {r['fuzz']:.1f} s, suite {r['suite']:.1f} s, "
                    f"command {r['command']:.1f} s")

    def cell(values: list[float], digits: int) -> str:
        return f"{statistics.median(values):.{digits}f} ({min(values):.{digits}f}-{max(values):.{digits}f})"

    head = ["measure", "target", f"{base.name}: median (range)", f"{this.name}: median (range)", "runs"]
    rows = []
    labels = {"ready": "launch to `ready`", "first": "STREAM request to the first sample",
              "fifth": "STREAM request to the fifth sample", "launch_to_first": "launch to the first sample"}
    for t in targets:
        for key, label in labels.items():
            rows.append([label, t, cell([r[key] for r in boots[base.name, t]], 3),
                         cell([r[key] for r in boots[this.name, t]], 3), str(args.boots)])
    for key, label in (("fuzz", "HIL suite: fuzz, 10,000 frames"), ("suite", "HIL suite: all checks"),
                       ("command", "`emulate --suite`: build, boot, suite")):
        if args.suites:
            rows.append([label + " (s)", "mps2", cell([r[key] for r in suites[base.name]], 1),
                         cell([r[key] for r in suites[this.name]], 1), str(args.suites)])
    print(f"Seconds; {args.boots} boots per target and version, {args.suites} suite runs per version, "
          "alternating; load average at the end "
          f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores.\n")
    print(table(head, rows))


if __name__ == "__main__":
    main()
