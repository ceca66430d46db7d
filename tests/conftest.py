"""Shared test helpers. Under CI (CI=true) a missing external tool fails the test instead of skipping it."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys

import pytest

IN_CI = os.environ.get("CI", "").lower() in ("1", "true", "yes")


def require_tool(name: str) -> str:
    """Path of an external tool; skip locally, fail under CI, when it is absent."""
    path = shutil.which(name)
    if path is None:
        msg = f"{name} is not installed (scripts/test installs it)"
        if IN_CI:
            pytest.fail(msg)
        pytest.skip(msg)
    return path


# A shell without job control starts a background job (`bash scripts/test &`, nohup) with SIGINT ignored, and its
# children inherit that: a command under test would never see the Ctrl-C a test sends it. Handled here, SIGINT is
# back at its default in every child, as under a terminal.
if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)
# Likewise SIGCHLD: inherited as ignored, children are reaped unasked and every exit status reads 0.
if signal.getsignal(signal.SIGCHLD) == signal.SIG_IGN:
    signal.signal(signal.SIGCHLD, signal.SIG_DFL)


def run_cli(*args, input=None, cwd=None):
    """Run a console script's module as a subprocess; returns CompletedProcess (text)."""
    tool, rest = args[0], list(args[1:])
    module = {"fitgen": "fitgen.app.cli", "tactile-host": "fitgen.app.host_cli", "tactile-hil": "fitgen.app.hil_cli"}[tool]
    code = f"import sys; from {module} import main; sys.argv[0] = {tool!r}; main()"
    return subprocess.run([sys.executable, "-c", code, *rest], capture_output=True, text=True,
                          input=input, cwd=cwd, timeout=600)


# Progress lines are cut to COLUMNS where it is set: the tests draw them on a terminal of unknown width, 80 columns
os.environ.pop("COLUMNS", None)
CLEARED = "\r" + " " * 79 + "\r"  # a progress line erased on such a terminal


class Terminal:
    """A stderr that says it is a terminal, keeping what is written (fitgen.base.progress.Progress draws on one)."""

    def __init__(self):
        self.text = ""

    def isatty(self):
        return True

    def write(self, text):
        self.text += text

    def flush(self):
        pass


def twin_and_another_unit(folder):
    """Units 7 and 8 of paper in volts, simulated on the slide scene (``u7.unit.toml``, ``u8.unit.toml`` in
    ``folder``), and unit 7's twin as ``fitgen fit`` writes it (``twin.json``): the model, loaded."""
    from pathlib import Path

    from fitgen.equations.model import load_model

    folder = Path(folder)
    for seed in (7, 8):
        proc = run_cli("fitgen", "simulate", "--sensor", "paper", "--unit", str(seed), "--transfer", "gmr", "--scene",
                       "slide", "-o", str(folder / f"u{seed}.csv"))
        assert proc.returncode == 0, proc.stderr
    proc = run_cli("fitgen", "fit", str(folder / "u7.csv"), "-o", str(folder / "twin.json"), "--family", "all",
                   "--held-out", "50")
    assert proc.returncode == 0, proc.stderr
    return load_model(folder / "twin.json")


def simulated_capture(unit, poses, seed, rig_error=0.01, samples=16):
    """A simulated capture of ``unit`` at stage ``poses``: the stage off its labels by the rig's error, rows averaged
    over ``samples`` (the unit's noise over sqrt(samples)); the readings and that noise."""
    import numpy as np

    from fitgen.physics.simulate import rig_poses
    from fitgen.physics.transfer import readings

    rng = np.random.default_rng(seed)
    true = rig_poses(poses, rig_error, rng)
    noise = unit.noise / np.sqrt(samples)
    return readings(unit, true, adc_bits=0) + rng.normal(0.0, noise, (len(poses), unit.n_elements)), noise


def save_capture(path, y, poses, meta=None):
    """Readings ``y`` at stage poses (their dx, dy, dz) saved as a capture in volts, with ``meta`` besides; the path."""
    from fitgen.physics.dataset import Dataset

    Dataset(y, poses[:, :3], ("dx", "dy", "dz"), {"units": "V", **(meta or {})}).save(path)
    return path


def interrupt_after_rename(monkeypatch, under=None) -> list:
    """``os.replace`` patched to raise SIGINT right after its first real rename (of a file in folder ``under``,
    when given): a Ctrl-C landing between two of a command's writes. The renamed targets, in order."""
    real, renamed = os.replace, []

    def replace(src, dst):
        real(src, dst)
        if under is None or os.path.dirname(dst) == str(under):
            renamed.append(dst)
            if len(renamed) == 1:
                signal.raise_signal(signal.SIGINT)

    monkeypatch.setattr(os, "replace", replace)
    return renamed


def assert_one_line_error(proc, status: int = 2, contains: str | None = None):
    assert proc.returncode == status, (proc.returncode, proc.stdout, proc.stderr)
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, proc.stderr
    assert "Traceback" not in proc.stderr
    if contains:
        assert contains in lines[0], lines[0]


# --- the sensor and model the readout tests share (volts, as an ADC sees them) ---------------


@pytest.fixture(scope="session")
def sensor():
    """The paper sensor in its ``gmr`` transfer: element outputs in volts."""
    from fitgen.physics.sensor import load_sensor

    return load_sensor("paper").with_transfer("gmr")


@pytest.fixture(scope="session")
def model(sensor):
    """A model fitted on that sensor's paper-sim grid, the paper's way (the readout tests' tolerances are
    this model's; the device's fit is tests/test_deployed.py's)."""
    from fitgen.fitting.fit import FitSettings, fit_model
    from fitgen.physics.simulate import PAPER_GRIDS, grid_poses, simulate

    return fit_model(simulate(sensor, grid_poses(PAPER_GRIDS["paper-sim"])), settings=FitSettings.exact())


@pytest.fixture(scope="session")
def device_model(sensor):
    """The same sensor fitted as a device model is (noise- and float-aware, the default), on a 675-pose grid."""
    from fitgen.fitting.fit import FitSettings, fit_model
    from fitgen.physics.simulate import grid_poses, simulate

    grid = grid_poses({"dx": [-2, -1, 0, 1, 2], "dy": [-2, -1, 0, 1, 2], "dz": [0, -1, -2], "thx": [-5, 0, 5],
                       "thy": [-5, 0, 5]})
    return fit_model(simulate(sensor, grid), settings=FitSettings())


# the set-up the C-driver tests share: two ADS1115 reading the paper sensor's 8 elements, magnet at a pose
TWO_CHIPS = "ads1115@0x48:0-3,ads1115@0x49:0-3"
GMR_POSE = [0.5, 0.2, -1.0, 1.0, 0.0]


def drifting_bus(cmap, drift, tin):
    """(SimBus at GMR_POSE with 0.5 mV noise, the elements drifting by ``drift`` and the thermistor at ``tin`` at its
    temperature, its VirtualClock): a fresh one per run gives the same readings."""
    from fitgen.physics.sensor import load_sensor
    from host.clock import VirtualClock
    from host.simbus import SimBus

    clock = VirtualClock()
    return SimBus.for_channel_map(cmap, load_sensor("paper").with_transfer("gmr"), GMR_POSE, clock=clock,
                                  noise=0.0005, seed=3, drift=drift, thermistor=tin), clock


def sim_bus(spec=TWO_CHIPS, faults=(), settings=None, seed=3):
    """(channel map, SimBus with 0.5 mV noise at GMR_POSE, its VirtualClock), with ``faults`` injected."""
    from fitgen.physics.sensor import load_sensor
    from host.channelmap import Settings, parse_spec
    from host.clock import VirtualClock
    from host.simbus import SimBus

    cmap = parse_spec(spec, settings or Settings())
    clock = VirtualClock()
    bus = SimBus.for_channel_map(cmap, load_sensor("paper").with_transfer("gmr"), GMR_POSE, clock=clock,
                                 noise=0.0005, seed=seed)
    for f in faults:
        bus.inject(**f)
    return cmap, bus, clock


@pytest.fixture(scope="session")
def model_file(model, tmp_path_factory):
    return str(model.save(tmp_path_factory.mktemp("model") / "model.json"))


def model_for_sensor(model, name: str, path) -> str:
    """``model`` saved to ``path`` with its held-out record naming sensor ``name`` (a unit file's, as identify
    names it): what flash and emulate take the device's sensor id from."""
    import dataclasses

    held = {**(model.fit_info.get("held_out") or {}), "sensor": name}
    return str(dataclasses.replace(model, fit_info={**model.fit_info, "held_out": held}).save(path))


def emulated_suite(model, held_out, style: str, n: int = 500):
    """The whole HIL suite against ``model`` built (float, ``style``) into the emulated Cortex-M4 (mps2)."""
    require_tool("qemu-system-arm")
    require_tool("arm-none-eabi-gcc")
    from hil.emulate import start_target
    from hil.suite import run_suite
    from host.device import Device

    with start_target(model, "mps2", precision="float", style=style) as emu:
        with Device.open(emu.url, timeout=5) as dev:
            return run_suite(dev, model, url=emu.url, n_vectors=n, n_fuzz=n, verbose=False, held_out=held_out)


def assert_c_equals_python(model, inputs):
    """gcc's double and float builds, table and unrolled, give Model.predict's outputs and status bit for bit."""
    import numpy as np
    from fitgen.c.compiled import CompiledModel

    require_tool("gcc")
    for precision in ("double", "float"):
        for style in ("table", "unrolled"):
            with CompiledModel(model, precision, style) as cm:
                out, status = cm.predict(inputs)
            ref, ref_status = model.predict(inputs, with_status=True, precision=precision)
            np.testing.assert_array_equal(status, ref_status)
            np.testing.assert_array_equal(out, ref)


def verify_on_arm_linux(model, precision: str, style: str):
    """verify() of ``model``'s C built for 32-bit ARM Linux, run under qemu-arm on 300 random vectors: it must pass."""
    from fitgen.c.verify import verify

    require_tool("arm-linux-gnueabihf-gcc")
    require_tool("qemu-arm")
    res = verify(model, precision, style, cc="arm-linux-gnueabihf-gcc -static", runner="qemu-arm", n_random=300)
    assert res.ok, res.failures
    return res
