"""The ``complete`` error model (kincal's default): MD-H plus Hayati's beta at nearly
parallel axes.

Plain MD-H (:mod:`kincal.models.mdh`) describes the line of axis i+1 relative to axis i
by four numbers, but where the two axes are parallel one of them (d_i) only slides that
line along itself: the tilt of axis i+1 within the plane of the two axes cannot be
expressed, so a real arm's small misalignment of its parallel joints (every UR arm, the
EC66, ... at joints 2-3-4) stays in the residuals. Hayati's beta, a turn about the y axis
of frame i after its twist alpha, restores it; ``d`` stays in the model and the
rank-revealing selection drops whichever d the data cannot tell apart.

Threshold: a pair of consecutive axes within NEARLY_PARALLEL_DEG of parallel gets beta,
with frame i's x axis pointing to where axis i+1 pierces the plane normal to axis i at
frame i's origin (see :func:`kincal.models.mdh.extract`). That point, and so every
parameter, moves smoothly as the axes tilt through parallel: the model is continuous
there, where MD-H's common normal runs off to infinity (at 1e-4 rad its foot lies
thousands of link lengths away). Above the threshold MD-H's common normal is at most
1/tan(10 deg) = 5.7 times the axes' offset away, a well-conditioned description; the
two descriptions are both complete, so the threshold changes the parametrisation, not
what can be fitted. Complete (every small geometric error of the arm is representable, up
to what the measurement frame and tool absorb), continuous, and minimal after the
selection. Suits every serial arm; ``mdh`` remains for the paper's reproduction.
"""

from __future__ import annotations

import math

from kincal.models import mdh

NEARLY_PARALLEL_DEG = 10.0  # consecutive axes within this angle of parallel get a beta


def build(geometry) -> mdh.MdhModel:
    """The complete model of a :class:`kincal.models.geometry.ChainGeometry`."""
    return mdh.extract(geometry, beta_below=math.sin(math.radians(NEARLY_PARALLEL_DEG)),
                       name="complete")
