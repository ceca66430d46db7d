"""The mechanics of a simulated G-code stage (host.stagesim's controllers drive it).

``SimRig``: the carriage's position (machine coordinates plus the offset a reset or homing sets), the tool's true
position behind it (a dead band of ``backlash`` mm per axis, then a fresh Gaussian ``repeatability`` error at the
end of every move), and the magnet's pose: while the tool is in contact (its pose-dz at most ``adhesion`` above
first contact), magnet displacement = ``M @`` tool displacement from first contact (in the sensor's axes, through
the true axis map); otherwise the magnet rests. The contact is decided here, on the tool: a ``SensorFeed`` driven
by a rig is set ``touching`` so that a built unit does not judge the magnet's dz as a label's again (its own map
then acts after ``M``). It hands the pose to ``target.set_pose``: a
``host.simbus.SensorFeed`` or ``SimBus`` in the same process, or a ``PoseFile`` that a capture in another process
follows (``capture --simulate --sim-pose-file``).
"""

from __future__ import annotations

import threading

import numpy as np

from fitgen.base.errors import InputError
from fitgen.physics.pose import OFF_SKIN_MM

from host.gcode import MACHINE_AXES
from host.stagesettings import APPROACH, STAGE_AXES, AxisMap, parse_approach

MAX_SLACK = 1.0  # mm: a stage's backlash or repeatability past it is broken, not one to calibrate a sensor on


class SimRig:
    """Carriage -> tool (backlash, repeatability) -> magnet (contact, map ``M``) -> ``target.set_pose``."""

    def __init__(self, target=None, M=None, *, axes: str = "X=dx,Y=dy,Z=dz", contact=(12.0, 8.0, 4.0),
                 start=(10.0, 10.0, 10.0), backlash=0.03, repeatability=0.002, adhesion=OFF_SKIN_MM,
                 travel=((0.0, 200.0),) * 3, seed: int = 0):
        self.target = target
        self.M = np.eye(3) if M is None else np.asarray(M, dtype=float).reshape(3, 3)
        self.axes = AxisMap.parse(axes, "--axes")  # the rig's true machine -> sensor axes
        self.contact = np.asarray(contact, dtype=float)  # carriage position (home frame) at first contact
        self.backlash = np.broadcast_to(np.asarray(backlash, dtype=float), (3,)).copy()
        self.repeatability = float(repeatability)
        for name, value in (("backlash", self.backlash), ("repeatability", np.array([self.repeatability]))):
            bad = value[~((0 <= value) & (value <= MAX_SLACK))]
            if bad.size:  # past it, no stage to calibrate on (and 1e308 mm overflows a move)
                raise InputError(f"--{name} must be 0..{MAX_SLACK:g} mm (a printer's is 0.01-0.1), got {bad[0]:g}")
        self.adhesion = float(adhesion)
        self.travel = np.asarray(travel, dtype=float)  # carriage range in the home frame
        for name, at in (("contact", self.contact), ("start", np.asarray(start, dtype=float))):
            if np.any((at < self.travel[:, 0]) | (at > self.travel[:, 1])):  # a sensor no move reaches; past a stop
                raise InputError(f"--{name} {','.join(f'{v:g}' for v in at)} lies outside the rig's travel ("
                                 + ", ".join(f"{a} {lo:g}..{hi:g}" for a, (lo, hi) in zip("XYZ", self.travel))
                                 + " mm from the home switches)")
        # where homing puts the carriage (home frame), machine 0 once homed: every axis's minimum, as a printer's
        # endstops (Marlin homes Z down, onto the bed); a GRBL controller puts Z's at the top (host.stagesim)
        self.switches = np.zeros(3)
        self.rng = np.random.default_rng(seed)
        self.carriage = np.asarray(start, dtype=float).copy()  # where the motors put the carriage (home frame)
        self.start = self.carriage.copy()  # machine 0 until homed
        # the tool lags the carriage by half the backlash, on the side it last came from (unknown at power-on:
        # centred)
        self.nominal = self.carriage.copy()
        self.tool = self.carriage.copy()
        self.pose = np.zeros(5)
        self.lock = threading.Lock()
        self.publish()

    def move(self, carriage) -> None:
        """The carriage reached ``carriage`` (home frame): the tool follows through the dead band."""
        with self.lock:
            c = np.asarray(carriage, dtype=float)
            half = self.backlash / 2
            self.nominal = np.where(c > self.nominal + half, c - half, np.where(c < self.nominal - half, c + half,
                                                                                 self.nominal))
            self.carriage = c.copy()
            self.tool = self.nominal + self.rng.normal(0.0, self.repeatability, 3) * (self.repeatability > 0)
            self.publish()

    def carriage_at_contact(self, approach=None) -> np.ndarray:
        """Where the carriage stands (home frame) when the tool is at first contact and each axis came from its
        ``approach`` side (pose axes; default the capture's): the zero a user finds by the documented jog."""
        c, approach = self.contact.copy(), parse_approach(APPROACH) if approach is None else approach
        for m, p, s in self.axes.pairs:
            k, j = MACHINE_AXES.index(m), STAGE_AXES.index(p)
            if approach[j]:
                c[k] -= s * np.sign(approach[j]) * self.backlash[k] / 2  # the carriage leads the tool by half
        return c

    def contact_note(self) -> str:
        """Where to jog for the zero (:meth:`carriage_at_contact`, the capture's default approach), in machine
        coordinates before homing (power-on puts machine 0 at the start) and after it (the switches are 0)."""
        at = self.carriage_at_contact()
        first = " ".join(f"{a}{c - s:.6g}" for a, c, s in zip("XYZ", at, self.start))
        homed = " ".join(f"{a}{c - s:.6g}" for a, c, s in zip("XYZ", at, self.switches))
        return (f"first contact at machine {first} ({homed} once homed; the carriage, each axis come from the "
                "capture's approach side: from -dx, -dy, above)")

    def displacement(self) -> np.ndarray:
        """The tool's displacement from first contact along the sensor's dx, dy, dz."""
        d = np.zeros(3)
        for m, p, s in self.axes.pairs:
            k = MACHINE_AXES.index(m)
            d[STAGE_AXES.index(p)] = s * (self.tool[k] - self.contact[k])
        return d

    def publish(self) -> None:
        d = self.displacement()
        pose = np.zeros(5)
        if d[2] <= self.adhesion:  # in contact (a little adhesion holds the skin when the tool just lifts)
            pose[:3] = self.M @ d
        self.pose = pose
        if self.target is not None:
            self.target.set_pose(pose)
