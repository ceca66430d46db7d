"""The readings a stage's error can carry across a knee, where no linearisation weighs them right.

identify (fitgen.fitting.identify) takes each row's covariance from the readings' slopes by the stage's displacement
at its label. A reading is a straight line of the stage only away from its knees: the field's zero on the element's
axis (the omnipolar |B . axis| folds there), the element's saturation, the ADC's rails. Within a few stage errors of
one, the rig's error carries the reading across it or not, and the reading stops moving with the row's other
readings as the slopes say: one the rig carried past the saturation, or one that stayed on the plateau where the
line said it would leave it, stood up to a hundred noise sd off what the row's other readings said of the stage, and
a capture made exactly to identify's own model was refused (an outside review: a unit of tilted-axes in 13, at a
reading its field's zero crossed; of ring-vertical in 200, at a saturation). Such a reading weighs nothing, as a
clipped one does.
"""

from __future__ import annotations

import numpy as np

from fitgen.physics.transfer import volts_per_mt

# stage errors (rms) within which a reading may cross a knee: at 5, one in 3.5 million
KNEE_REACH = 5.0
FOLD_GUARD = 3.0  # how many times the reach the line at a label may lie from its field's zero, its reading within it


def near_knees(space, theta: np.ndarray, readings: np.ndarray, line: np.ndarray, slopes: np.ndarray,
               reach: float) -> np.ndarray:
    """The readings (n, N) of a unit of ``space`` with parameters ``theta`` (physical units) that a stage's error
    of ``reach`` mm (KNEE_REACH of its rms, rig and zero together) could carry across a knee, given each reading's
    ``line`` at its label (n, N: unsaturated and unclipped) and the line's ``slopes`` by the stage (n, N, 3): the
    line lies within its slope times ``reach`` of its field's zero, its element's saturation or an ADC rail, or the
    reading read lies that near its field's zero and the line within FOLD_GUARD times that (there the line folds,
    and a reading the rig carried across reads on the side the label's does: the fit's unit, until it has
    converged, may put the fold a little elsewhere)."""
    if reach <= 0:
        return np.zeros(readings.shape, dtype=bool)
    band = reach * np.sqrt(np.sum(slopes**2, axis=-1))
    p = space._parts(np.asarray(theta, dtype=float)[None])
    d = space.drawing
    if d.transfer == "raw":  # the reading at the field's zero; quantised, the ADC's rails
        knees = [p["off"][0]] + ([d.raw.full_scale, 0.0] if d.raw.adc_bits > 0 else [])
    else:
        g = d.gmr
        top = g.offset + volts_per_mt(g) * (p["gain"][0] * g.saturation + p["off"][0])
        knees = [g.offset + volts_per_mt(g) * p["off"][0], np.minimum(top, g.adc_max), g.adc_min]
    # the reading read near its field's zero, where the line is a few times that near too (not an element that
    # reads its offset alone, dead, whose line lies far from it: that one the fit must see)
    near = (np.abs(readings - knees[0]) < band) & (np.abs(line - knees[0]) < FOLD_GUARD * band)
    for knee in knees:
        near |= np.abs(line - knee) < band
    return near & (band > 0)
