"""Recording a calibration dataset: for each pose of a schedule, wait, average, check, append one row.

The output is the shared dataset CSV (v1..vN in volts, then the schedule's pose columns) with ``<output>.meta.json``
beside it (units V, so ``fitgen fit`` makes a model in volts). Every row is one ``write`` of a complete line on a
file opened for appending, then ``fsync``: a row is on disk whole or not at all. A run that stops for any reason
(Ctrl-C, a kill, a power cut, a silent chip) loses no row; run the same command again and it resumes: a last line
without its newline (a write cut short) is dropped, and each schedule pose already in the file is skipped -- counted
with multiplicity, so a schedule may visit a pose twice.

The meta also records the noise the capture measured (:class:`NoiseStats`), the time it took, and whatever the
caller adds (the channel map, a stage's settings). It is rewritten at the start, at most every ``META_EVERY``
seconds and at the end of a run, so a run killed outright loses at most those seconds of figures, never a row.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fitgen.fitting.capturecheck import MAX_STAGE_ERROR, is_stage_error
from fitgen.physics.dataset import load_meta, meta_path, noise_figures_agree, pose_table, read_text
from fitgen.base.errors import InputError, shown
from fitgen.base.signals import signals_held
from fitgen.base.parse import MAX_NOISE, MAX_ROW_SAMPLES
from fitgen.physics.pose import POSE_NAMES, as_poses, box_problem, check_pose_rows
from fitgen.physics.simulate import sensor_record_problem

from host.adc import AdcArray
from host.capturefile import RowWriter, prepare_output, prior_meta, prior_row_degc, row_line, write_meta
from host.clock import REAL_CLOCK
from host.rest import measure

META_EVERY = 2.0  # seconds between rewrites of the meta during a run


class SpreadTooLarge(RuntimeError):
    """The readings of a pose kept moving more than allowed."""


SAMPLES = 16  # samples averaged per row when neither --samples nor the schedule names a number
MAX_COUNT = 10 ** 9  # an earlier run's noise_rows or runs past this is no count a capture wrote: counted anew


@dataclass(frozen=True)
class Schedule:
    poses: np.ndarray  # (P, 5)
    columns: tuple[str, ...]  # the pose columns the schedule names, in the order dx,dy,dz,thx,thy
    origin: str = "schedule"
    drawing: dict | None = None  # the drawing `fitgen schedule` made it for: sensor, sensor_file, sha256, transfer
    stage: dict | None = None  # the stage it was made for: rig_error, zero_error (mm), as `fitgen schedule` took them,
    # and rig_error_given: whether it was told the rig's error (fitgen check takes a check schedule's only then)
    check: bool = False  # `fitgen schedule --check`'s: random poses for a check capture, not a calibration's
    captured: str | None = None  # a capture given as the schedule: the schedule its meta names ('' for none)

    def capture_note(self) -> str:
        """A note when the schedule is a capture (its poses taken, its schedule's record not), else ''."""
        if self.captured is None:
            return ""
        was = f" {self.captured.removeprefix('schedule ')}" if self.captured else ""
        return (f"note: --poses {self.origin.removeprefix('schedule ')} is a capture, not a schedule: its poses are "
                f"taken, but not what its schedule{was} recorded (the drawing and the stage's errors it was made for, "
                "which identify and check read from the capture): give that schedule")

    @property
    def values(self) -> np.ndarray:
        """(P, len(columns)): what goes into the dataset's pose columns."""
        return self.poses[:, [POSE_NAMES.index(c) for c in self.columns]]

    def describe(self, i: int) -> str:
        return " ".join(f"{c}={v:g}" for c, v in zip(self.columns, self.values[i]))


def designed_samples(path: str | Path) -> int | None:
    """The samples per row schedule ``path`` was designed for (``samples_per_row`` in the meta `fitgen schedule`
    writes beside it), or None when it names none."""
    n = load_meta(path).get("samples_per_row")
    if n is None:
        return None
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise InputError(f"{meta_path(path)}: samples_per_row must be a whole number >= 1, got {shown(n)}; repair it, "
                         "or give --samples")
    if n > MAX_ROW_SAMPLES:  # a row would take hours
        raise InputError(f"{meta_path(path)}: samples_per_row must be at most {MAX_ROW_SAMPLES}, got {n}; repair it, "
                         "or give --samples")
    return n


def load_schedule(path: str | Path) -> Schedule:
    """A CSV with any of the columns dx,dy,dz,thx,thy (fitgen.physics.dataset.pose_table); missing components are
    0."""
    origin = f"schedule {path}"
    poses, columns = pose_table(read_text(path, "schedule"), origin)
    check_pose_rows(poses, origin)  # a pose of 1e308 mm had been reached only after the rows before it
    meta = load_meta(path)
    drawing = {k: meta[k] for k in ("sensor", "sensor_file", "sensor_sha256", "transfer") if k in meta}
    stage = {k: meta[k] for k in ("rig_error", "rig_error_given", "zero_error", "ranges") if k in meta}
    bad = next((k for k in ("rig_error", "zero_error") if k in stage and not is_stage_error(stage[k])), None)
    # the capture passes these on to identify and check, which would read them only after every row was taken
    ranges = box_problem(stage["ranges"]) if "ranges" in stage else ""  # where identify names poses to capture
    problem = (f"{bad} must be 0..{MAX_STAGE_ERROR:g} mm, got {stage[bad]!r}" if bad else
               f"rig_error_given must be true or false, got {stage['rig_error_given']!r}"
               if not isinstance(stage.get("rig_error_given", False), bool) else
               f"ranges {ranges}" if ranges else sensor_record_problem(drawing))
    if problem:
        raise InputError(f"{meta_path(path)}: {problem}; repair it, or make the schedule again")
    captured = None
    if str(meta.get("generator", "")).startswith("tactile-host capture"):  # as fitgen.app.outputkind.is_capture tells
        captured = meta["schedule"] if isinstance(meta.get("schedule"), str) else ""
    return Schedule(as_poses(poses), columns, origin, drawing if "sensor" in drawing else None, stage or None,
                    meta.get("check") is True, captured)


def simulated_sensor(args, schedule: Schedule) -> None:
    """Without ``--sensor``, a simulated capture simulates the drawing its schedule was made for, where its file is
    here unchanged (else ADC_DEFAULTS' paper): a four-element schedule of one's own simulated eight elements."""
    from fitgen.physics.simulate import recorded_spec

    if args.sensor is None and args.simulate:
        args.sensor = recorded_spec(schedule.drawing)


@dataclass
class CaptureResult:
    total: int  # poses in the schedule
    before: int  # poses already in the file at the start
    captured: int = 0  # rows written by this run
    stopped: bool = False  # the user stopped before the end
    dropped_partial: bool = False
    spreads: list = field(default_factory=list)  # max spread (V rms) of each row written
    noise: "NoiseStats | None" = None  # the noise pooled over the file's rows (earlier runs' too)

    @property
    def complete(self) -> bool:
        return self.before + self.captured == self.total


@dataclass
class NoiseStats:
    """The element noise measured over rows: each row's sample variance (ddof 1) per element, pooled.

    ``sample_noise`` = sqrt(mean over rows of the variance): one sample's noise (V rms);
    ``row_noise`` = sqrt(mean over rows of variance / samples): the noise left in a row's average.
    """

    n_elements: int
    rows: int = 0
    sum_var: np.ndarray | None = None  # sum over rows of the per-element sample variance, V^2
    sum_var_row: np.ndarray | None = None  # ... of variance / samples of that row

    def __post_init__(self):
        if self.sum_var is None:
            self.sum_var = np.zeros(self.n_elements)
        if self.sum_var_row is None:
            self.sum_var_row = np.zeros(self.n_elements)

    def add(self, block: np.ndarray) -> None:
        if block.shape[0] < 2:
            return  # one sample has no spread to measure
        var = block.var(axis=0, ddof=1)
        self.rows += 1
        self.sum_var += var
        self.sum_var_row += var / block.shape[0]

    @classmethod
    def from_meta(cls, meta: dict, n: int) -> "NoiseStats":
        """The figures an earlier run recorded (pooled over ``noise_rows`` rows: rows deleted to be taken again
        count too), to pool on from; none when they are not figures a capture writes (this run's then stand alone)."""
        try:
            rows, samples = int(meta["noise_rows"]), int(meta["samples_per_row"])
            ns, nr = np.asarray(meta["sample_noise"], dtype=float), np.asarray(meta["row_noise"], dtype=float)
        except (KeyError, TypeError, ValueError, OverflowError):
            return cls(n)
        if not 1 <= rows <= MAX_COUNT or not 1 <= samples <= MAX_ROW_SAMPLES or ns.shape != (n,) or \
                nr.shape != (n,) or not np.all((ns >= 0) & (ns <= MAX_NOISE) & (nr >= 0) & (nr <= MAX_NOISE)):
            return cls(n)  # NaN fails the bounds too
        if not noise_figures_agree(ns, nr, samples):  # not from the same samples
            return cls(n)
        return cls(n, rows, rows * ns ** 2, rows * nr ** 2)

    def meta(self) -> dict:
        if self.rows == 0:
            return {"noise_rows": 0, "sample_noise": None, "row_noise": None}
        return {"noise_rows": self.rows,
                "sample_noise": [float(x) for x in np.sqrt(self.sum_var / self.rows)],
                "row_noise": [float(x) for x in np.sqrt(self.sum_var_row / self.rows)]}


def capture(array: AdcArray, schedule: Schedule, output: str | Path, *, samples: int = SAMPLES,
            max_spread: float = 0.003, tries: int = 3, wait=None, set_pose=None, settle: float = 0.0,
            clock=REAL_CLOCK, progress=None, meta: dict | None = None, temperature=None) -> CaptureResult:
    """Capture every pose of ``schedule`` not yet in ``output``.

    Per pose: ``set_pose(pose)`` (a stage that moves itself: simulated, or
    ``host.stage.PoseStage.move_to``), ``wait(i, pose)`` (Enter or a
    trigger; False stops), ``settle`` seconds, then ``samples`` readings averaged;
    when some element's standard deviation exceeds ``max_spread`` volts the pose is
    measured again, up to ``tries`` times, then ``SpreadTooLarge``. ``temperature()`` (degC, a thermistor's):
    read before and after each row's samples, their mean recorded per row as the meta's ``row_degc``.
    """
    if samples < 1:
        raise InputError(f"--samples must be >= 1, got {samples}")
    if not max_spread > 0:
        raise InputError(f"--max-spread must be > 0 V, got {max_spread}")
    if tries < 1:
        raise InputError(f"--tries must be >= 1, got {tries}")
    if settle < 0:
        raise InputError(f"--settle must be >= 0 s, got {settle}")
    state = prepare_output(output, array.n, schedule)
    res = CaptureResult(len(schedule.poses), int(state.done.sum()), dropped_partial=state.dropped_partial)
    prior = prior_meta(output, state.rows)  # rows from earlier runs: pool on from their figures
    noise = res.noise = NoiseStats.from_meta(prior, array.n)
    try:  # an earlier run's counts, as its meta kept them; damaged ones start anew, as the noise figures do
        before_s, runs = float(prior.get("duration_s", 0.0)), int(prior.get("runs", 0)) + 1
    except (TypeError, ValueError, OverflowError):
        before_s, runs = 0.0, 1
    if not (math.isfinite(before_s) and before_s >= 0) or not 1 <= runs <= MAX_COUNT:
        before_s, runs = 0.0, 1
    t_start = clock.monotonic()
    info = {"schedule": schedule.origin, "schedule_poses": len(schedule.poses), "samples_per_row": samples,
            "max_spread_volts": max_spread,
            **({"schedule_drawing": schedule.drawing} if schedule.drawing else {}),
            **({"schedule_stage": schedule.stage} if schedule.stage else {}),
            **({"schedule_check": True} if schedule.check else {}), **(meta or {})}
    temps = prior_row_degc(output, prior, state.rows) if temperature is not None else None
    if temps is not None:
        info["row_degc"] = temps

    def refresh():
        info.update(noise.meta(), duration_s=before_s + (clock.monotonic() - t_start), runs=runs)
        write_meta(output, info)
        return clock.monotonic()

    if prior and state.done.all():  # nothing left to capture: the meta stays as the runs that did left it
        return res
    writer = RowWriter(output)  # before the meta: a run refused (a read-only output) leaves both as they were
    values = schedule.values
    try:
        last_meta = refresh()
        for i in np.flatnonzero(~state.done):
            pose = schedule.poses[i]
            if set_pose is not None:
                set_pose(pose)
            if wait is not None and not wait(int(i), pose):
                res.stopped = True
                break
            clock.sleep(settle)
            for attempt in range(tries):
                before = temperature() if temps is not None else None
                block = measure(array, samples)
                spread = block.std(axis=0)
                if spread.max() <= max_spread:
                    break
            else:
                k = int(np.argmax(spread))
                raise SpreadTooLarge(f"pose {i + 1}/{res.total} ({schedule.describe(i)}): v{k + 1} spreads "
                                     f"{spread[k] * 1e3:.3g} mV rms over {samples} samples (limit "
                                     f"{max_spread * 1e3:.3g} mV) in {tries} tries; is the sensor still moving?")
            if temps is not None:  # in the meta before the row: a run killed between the two keeps them aligned
                temps.append(round(0.5 * (before + temperature()), 4))
                last_meta = refresh()
            with signals_held():  # a Ctrl-C in the row's fsync: the row is on disk, so it is counted with its noise
                writer.append(row_line(block.mean(axis=0), values[i]))
                res.captured += 1
                noise.add(block)
                res.spreads.append(float(spread.max()))
            if progress is not None:
                progress.update(1)
            if clock.monotonic() - last_meta >= META_EVERY:
                last_meta = refresh()
    finally:
        with signals_held():  # a second Ctrl-C here would leave the meta behind the rows (four runs in 33 did)
            writer.close()
            if temps is not None:  # a run stopped after a row's temperature but before its row: the rows written
                del temps[state.rows + res.captured:]
            refresh()
    return res
