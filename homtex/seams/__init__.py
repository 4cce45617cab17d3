"""Seamed spacer fabrics: seam cells, sewing, cushion profiles and seamed compression.

Two seam models answer ``seam_profile``: the yarn-level seam cell (:mod:`homtex.seams.yarn`)
and the analytical beam-on-foundation model (:mod:`homtex.seams.foundation`).
``seam_compression`` (:mod:`homtex.seams.compress`) presses a sewn seam cell between plates.
"""

from .compress import seam_compression
from .foundation import (
                         SLACK_LONG_NAME,
                         calibrate_layer_rigidity,
                         fabric_modulus,
                         foundation_profile,
                         layer_rigidity,
                         stitch_pull,
)
from .measure import measure_profile, thread_escape
from .yarn import SeamSolver, seam_profile, yarn_profile

__all__ = ["SLACK_LONG_NAME", "SeamSolver", "calibrate_layer_rigidity", "fabric_modulus", "foundation_profile",
           "layer_rigidity", "measure_profile", "seam_compression", "seam_profile", "stitch_pull", "thread_escape",
           "yarn_profile"]
