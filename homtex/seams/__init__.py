"""Seamed spacer fabrics: seam cells, sewing, cushion profiles and seamed compression."""

from .yarn import (SLACK_LONG_NAME, SeamSolver, calibrate_layer_rigidity, compression_summary, fabric_modulus,
                   foundation_profile, layer_rigidity, measure_profile, seam_compression, seam_profile,
                   stitch_pull, thread_escape, yarn_profile)

__all__ = ["SLACK_LONG_NAME", "SeamSolver", "calibrate_layer_rigidity", "compression_summary", "fabric_modulus",
           "foundation_profile", "layer_rigidity", "measure_profile", "seam_compression", "seam_profile",
           "stitch_pull", "thread_escape", "yarn_profile"]
