"""A unit's readings drawn with magpylib, written from the unit's sensor file alone: the independent
truth that tests/test_units.py and bench/units.py hold fitgen's unit physics to."""

from __future__ import annotations

import magpylib as magpy
import numpy as np
from scipy.spatial.transform import Rotation

OE_PER_MT = 10.0


def magpylib_readings(sensor, poses: np.ndarray, stage_field=None) -> np.ndarray:
    """Readings (P, N) of ``sensor`` (a drawing or a unit) at label poses, noise-free, no ADC quantisation;
    ``stage_field`` (3, 3; mT/mm): a field that moves with the stage, its value stage_field @ (dx, dy, dz) of the
    label (where the stage is, a lifted indenter too) added to the ambient field.

    The magnet: magpylib's Cylinder with the unit's polarisation, rest centre + map @ (dx, dy, dz) (a press dz
    shortened to dz (1 - stiffening |dz|)), and
    orientation Ry(thy) Rx(thx) of the pose after the unit's rest tilt; the field along each element's axis
    plus the ambient field's; then |.|, the element's gain and offset, and the transfer. A label (a unit's or a
    drawing's) more than 0.05 mm above first contact (dz) has lifted the indenter off the skin: the magnet rests.
    """
    poses = np.atleast_2d(np.asarray(poses, dtype=float)).copy()
    carried = None if stage_field is None else poses[:, :3] @ np.asarray(stage_field, dtype=float).T
    poses[poses[:, 2] > 0.05] = 0.0
    if not sensor.is_drawing:
        press = poses[:, 2] < 0  # an elastomer that stiffens: the magnet follows a press less the deeper it goes
        poses[press, 2] *= 1.0 + sensor.stiffening * poses[press, 2]
    mag = sensor.magnet
    rest = Rotation.from_euler("xy", mag.tilt, degrees=True)
    pose_rot = Rotation.from_euler("xy", poses[:, 3:5], degrees=True)
    cyl = magpy.magnet.Cylinder(
        dimension=(mag.diameter, mag.height),
        polarization=(0.0, 0.0, mag.polarization),
        position=np.asarray(mag.rest_center) + poses[:, :3] @ np.asarray(sensor.stage_map).T,
        orientation=pose_rot * rest,
    )
    B = cyl.getB(magpy.Sensor(pixel=sensor.positions)) * 1e3  # (P, N, 3) mT
    b = np.einsum("pnj,nj->pn", B, sensor.axes) + sensor.axes @ sensor.ambient
    if carried is not None:
        b = b + carried @ sensor.axes.T
    m = np.abs(b)
    if sensor.transfer == "raw":
        return sensor.gains * m + sensor.offsets
    g = sensor.gmr
    vpm = g.supply * g.sensitivity * 1e-3 * OE_PER_MT * g.gain
    return np.clip(g.offset + vpm * (sensor.gains * np.minimum(m, g.saturation) + sensor.offsets), g.adc_min, g.adc_max)
