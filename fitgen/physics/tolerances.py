"""How far a built unit may differ from its drawing: the spreads a maker expects (a sensor file's
``[tolerances]``), their defaults and the largest each may be."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Tolerances:
    """The spreads a maker expects between a built unit and its drawing, as standard deviations
    (fitgen.physics.units draws them normal, clipped at 3 sigma). Sources: docs/calibration.md."""

    magnet_offset_xy: float = 0.2  # mm, each of x and y: a magnet placed by hand in a cast elastomer
    magnet_offset_z: float = 0.12  # mm: the casting's thickness
    magnet_tilt: float = 2.0  # deg, each of thx and thy
    polarization: float = 0.03  # relative: the magnet grade's remanence band and batch spread
    element_azimuth: float = 1.0  # deg
    element_radius: float = 0.08  # mm: hand placement or pick-and-place and solder float
    element_height: float = 0.04  # mm: solder and board flatness
    element_axis: float = 2.0  # deg, the sensitive axis turned in the board's plane
    element_tilt: float = 1.0  # deg, the axis raised out of it (a part not flat on its pads)
    gain: float = 0.077  # relative: AA003-02 sensitivity 2.0-3.2 mV/V/Oe read as 2.6 +- 3 sigma
    offset: float = 0.004  # mT, each element's offset after trimming
    ambient: float = 0.03  # mT, each component of a static ambient field (the Earth's is about 0.05 mT)
    stage_gain: float = 0.05  # relative, each diagonal entry of the stage-to-magnet map
    stage_cross: float = 0.02  # each off-diagonal entry: the magnet does not follow quite parallel
    # 1/mm: an elastomer that stiffens as it is pressed (a press dz reaches the magnet as dz (1 - c |dz|)). 0 by
    # default, the magnet following the stage linearly; docs/calibration.md says when to allow for it
    stiffening: float = 0.0
    # mT/mm, each entry of a field the stage carries (its motors, a steel bed): the capture's, not the unit's. 0 by
    # default; docs/calibration.md says when to allow for it
    stage_field: float = 0.0

    def to_dict(self) -> dict:
        return {k: v for k, v in vars(self).items() if k not in ("stiffening", "stage_field") or v}


# the greatest stiffening (1/mm) a unit may have: 3 mm deep the magnet follows a press by 70 %
STIFFENING_MAX = 0.1
# the largest spread a [tolerances] key takes: past it a 3-sigma unit is no built unit of the drawing (a negative
# gain or stage map, the magnet out of its pocket, an element's axis turned by a right angle)
TOLERANCE_MAX = {"magnet_offset_xy": 1.0, "magnet_offset_z": 0.5, "magnet_tilt": 15.0, "polarization": 0.2,
                 "element_azimuth": 10.0, "element_radius": 0.5, "element_height": 0.3, "element_axis": 15.0,
                 "element_tilt": 15.0, "gain": 0.25, "offset": 0.2, "ambient": 0.3, "stage_gain": 0.2,
                 "stage_cross": 0.2, "stiffening": STIFFENING_MAX / 3, "stage_field": 0.1}
