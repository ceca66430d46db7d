import pytest

from conftest import CLEARED, assert_one_line_error, require_tool, run_cli
from fitgen.base.errors import InputError


def test_demo_runs_end_to_end(tmp_path):
    for tool in ("gcc", "qemu-system-arm", "arm-none-eabi-gcc"):
        require_tool(tool)
    out = tmp_path / "demo"
    proc = run_cli("fitgen", "demo", "--out", str(out))
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    for name in (".fitgen-demo", "paper-sim.csv", "paper-model.json", "random-2000.csv", "paper-report.md",
                 "c-float-table/tm_model.h", "c-double-table/tm_model.h"):
        assert (out / name).is_file(), name
    text = proc.stdout
    assert "dz: resolvable" in text
    assert "paper max" in text and "thx" in text
    # three headers verified by gcc, then the HIL suite on the emulated Cortex-M4
    assert text.count("PASS") == 4 and "FAIL" not in text
    assert "HIL suite on the emulated core: PASS" in text
    from fitgen.equations.model import load_model

    # the device's model says what it does on built units, flashed uncalibrated: far worse than on the drawing
    device = load_model(out / "device-model.json").fit_info["held_out"]
    assert "units built within the drawing's tolerances, flashed uncalibrated" in text
    for o, rec in device["uncalibrated"]["errors"].items():
        assert rec["noisy_max"] > 3 * device["errors"]["float"][o]["noisy_max"], o
    # a model in volts, and the line that opens the live view with it
    volts = load_model(out / "model-volts.json")
    assert volts.input_units == "V" and volts.fit_info["family"]["auto"]
    # with its held-out record, as `fitgen fit` writes one: verify and report measure rounding's share on it
    rec = volts.fit_info["held_out"]
    assert rec["sensor"] == "paper" and rec["poses"] == 2000
    assert all(0 < e["max"] for e in rec["errors"]["float"].values())
    assert f"tactile-host view --model {out / 'model-volts.json'} --adc" in text and "--simulate motion" in text
    # a built unit calibrated through the simulated stage: the twin beats the drawing's model on the unit's truth
    import re

    assert "40 poses captured through a simulated GRBL" in text and (out / "twin.toml").is_file()
    png = out / "identify.png"  # the test install has the plots extra: the figure is made
    assert f"what the capture determines, with the unit's truth -> {png}" in text and png.read_bytes()[:4] == b"\x89PNG"
    rows = {m.group(1): [float(x) for x in m.group(2, 4)] for m in
            re.finditer(r"^\s+(d[xyz]|th[xy])\s+([\d.e+-]+)\s+(\S+|\(no label\))\s+([\d.e+-]+)\s+[\d.e+-]+", text, re.M)}
    assert set(rows) == {"dx", "dy", "dz", "thx", "thy"}, text[-1500:]
    # the direct fit's rows are the capture's in contact (the header said 40, the schedule's rest rows included)
    from fitgen.physics.dataset import load_dataset, rows_on_the_skin

    on_skin = rows_on_the_skin(load_dataset(out / "capture.csv"))[0].n_rows
    assert on_skin < 40 and f"direct ({on_skin} rows)" in text
    # the tilts' error at rest is the ring's limit, said in words beside the table
    assert "thx and thy: one ring cannot tell a small tilt from a slide near rest" in text
    for name, (drawing, twin) in rows.items():
        assert twin < drawing / 5, (name, drawing, twin)
    # a check capture through the same stage: the twin as predicted there, the drawing's model far beyond it
    [twin_line] = [ln for ln in text.splitlines() if ln.startswith("   twin's model  ")]
    [drawing_line] = [ln for ln in text.splitlines() if ln.startswith("   drawing's model ")]
    assert twin_line.endswith(": as predicted") and drawing_line.endswith("it does not describe this unit")
    # the check capture moved from the calibration's zero, which the twin's posterior records: its rows stand where
    # identify found that zero, its standard error the zero's error
    assert re.search(r"^ +zero error [\d.]+ mm: the calibration's zero, reused \(X\S+ Y\S+ Z\S+ on a homed machine\): "
                     r"the rows stand at their labels plus where identify found that zero, dx [+-][\d.]+, "
                     r"dy [+-][\d.]+, dz [+-][\d.]+ mm \(standard error [\d.]+\)$", text, re.M), text[-1500:]
    from fitgen.physics.dataset import load_dataset

    assert load_dataset(out / "check.csv").n_rows == 30
    # both schedules carry the record `fitgen schedule` writes: the drawing, its hash, the stage, the samples per row
    from fitgen.physics.dataset import load_meta
    from fitgen.physics.sensor import load_sensor
    from host.capture import load_schedule

    gmr = load_sensor("paper").with_transfer("gmr")
    for name in ("schedule.csv", "check-poses.csv"):
        sched = load_schedule(out / name)
        assert sched.drawing == {"sensor": "paper", "sensor_sha256": gmr.sha256, "transfer": "gmr"}, name
        assert sched.stage["rig_error"] == 0.01 and sched.stage["rig_error_given"] is False, name
        assert load_meta(out / name)["samples_per_row"] == 16, name
    # the twin's model file says how it was fitted, as `fitgen fit` writes it: the family, and the rounding noise
    # where the fit's check raised it
    fam = load_model(out / "twin-model.json").fit_info["family"]
    assert fam["auto"] and fam["name"] in ("all", "harmonics")
    assert "rounding" not in fam or fam["rounding"]["factor"] > 8
    # fitted on the twin its unit file describes: report's sweep on that file takes the model (it refused it when
    # the demo fitted on the identification's own object, whose hash the file's is not)
    rep = run_cli("fitgen", "report", str(out / "twin-model.json"), "--data", str(out / "capture.csv"),
                  "--plot", str(tmp_path / "plots"), "--sensor", str(out / "twin.toml"))
    assert rep.returncode == 0, rep.stderr
    assert (tmp_path / "plots" / "sweep_thx.png").is_file()
    # and it names the unit file, as `fitgen fit` does: verify and the HIL suite simulate its held-out readings again
    # (without the file's path they could not, and said the rounding's share was not measured)
    from fitgen.fitting.holdout import clean_readings

    twin_model = load_model(out / "twin-model.json")
    assert twin_model.fit_info["held_out"]["sensor_file"] == str((out / "twin.toml").resolve())
    assert clean_readings(twin_model) is not None


def test_the_demo_writes_only_into_a_folder_of_its_own(tmp_path):
    """`fitgen demo -o .` in a project's folder wrote its own capture.csv, schedule.csv, check.csv and
    check-poses.csv over the project's (the names docs/calibration.md uses), without a word. A folder it wrote (its
    mark, or one from before it marked them) or an empty one it writes into."""
    from fitgen.app.demo import MARK, _own_folder

    (tmp_path / "capture.csv").write_text("v1,dz\n1.5,-1\n")
    proc = run_cli("fitgen", "demo", "--out", str(tmp_path))
    assert_one_line_error(proc, 2, f"{tmp_path} holds files no earlier demo wrote (capture.csv), and the demo writes "
                                   "capture.csv, schedule.csv, check.csv and more there over files of those names: "
                                   "give a new or empty folder (--out)")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["capture.csv"]
    demos = '{"fit": {"dataset": "old/paper-sim.csv"}}'  # as a demo before the mark wrote its model
    for held in ((), (MARK, "capture.csv"), ("paper-model.json", "paper-sim.csv", "capture.csv")):
        folder = tmp_path / f"f{len(held)}{held[:1]}"
        folder.mkdir()
        for name in held:
            (folder / name).write_text(demos if name == "paper-model.json" else "")
        _own_folder(folder)  # taken
    _own_folder(tmp_path / "none")
    # a model of one's own named paper-model.json is not a demo's: its capture.csv had been written over
    for model in ('{"fit": {"dataset": "capture.csv"}}', "not json", '{"fit": 1}'):
        (folder / "paper-model.json").write_text(model)
        with pytest.raises(InputError, match="holds files no earlier demo wrote"):
            _own_folder(folder)


def test_demo_bad_output_folder(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    proc = run_cli("fitgen", "demo", "--out", str(blocker / "sub"))
    assert proc.returncode == 2 and "Traceback" not in proc.stderr


def test_the_demos_fit_progress_line_is_cleared_when_the_fit_ends():
    """On a terminal the demo's fit line stayed after each fit ("fit [ ] 0/1 ... thx: step 1"), reading as a fit
    stopped at its first step."""
    import io

    from fitgen.app.demo import _fitting
    from fitgen.base.progress import Progress

    class Tty(io.StringIO):
        def isatty(self):
            return True

    tty = Tty()
    real = Progress.__init__
    try:
        Progress.__init__ = lambda self, label, total, stream=None, min_interval=0.0: real(self, label, total, tty, 0.0)
        with _fitting() as progress:
            progress("dx", 1, -10.0, 3)
            progress("dy", 1, -11.0, 4)
    finally:
        Progress.__init__ = real
    text = tty.getvalue()
    assert "dy: step 1, 4 terms" in text and "2/10" not in text and "1/10" in text
    assert text.endswith(CLEARED)
