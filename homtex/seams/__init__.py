"""Seamed spacer fabrics: seam cells, sewing, cushion profiles and seamed compression.

``seam_profile`` (:mod:`homtex.seams.profile`) answers with the yarn-level seam cell sewn on the
large-motion engine (:mod:`homtex.seams.sew`) or with the analytical beam-on-foundation model
(:mod:`homtex.seams.foundation`); ``seam_compression`` (:mod:`homtex.seams.compress`) presses a
sewn seam cell between plates (:mod:`homtex.seams.press`).
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
from .measure import leg_shortening, measure_profile, pile_legs, thread_escape
from .profile import engine_profile, paper_setting, seam_profile, sewn_seam
from .sew import SewnSeam, sew
from .yarn import SeamSolver, linear_profile

__all__ = ["SLACK_LONG_NAME", "SeamSolver", "SewnSeam", "calibrate_layer_rigidity", "engine_profile",
           "fabric_modulus", "foundation_profile", "layer_rigidity", "leg_shortening", "linear_profile",
           "measure_profile", "paper_setting", "pile_legs", "seam_compression", "seam_profile", "sew", "sewn_seam",
           "stitch_pull", "thread_escape"]
