"""Experiment: a tension-controlled stitch (constant thread tension, as a sewing machine's
tensioner sets it) instead of the legs' pre-strain, whose rest length caps the pinch.

The stitch legs become force elements (axial stiffness x1e-3, pre-load T per leg = two strands);
the threads along the seam carry the same T. If the beam-on-foundation bound of
studies/seam_length_scale.py holds for the yarn-level cell, a stronger stitch pulls the seam line
deeper while the cushion crest does NOT come down (it bulges up slightly).

    python studies/seam_tension_stitch.py      (~1 min; prints seam line and crest per tension)
"""
import time
from pathlib import Path

import numpy as np

import homtex
from homtex.geometry.seam import seam_cell
from homtex.seams import SeamSolver, measure_profile
from homtex.analysis.static import prestrain_load

cell = homtex.load_cell(Path(__file__).resolve().parents[1] / "cells" / "spacer_20mm.toml")
eps0 = 0.3
for d in (24.0,):
    for T in (0.5, 1.0, 2.0, 4.0, 8.0):
        t = time.time()
        frame, info = seam_cell(cell, seam_distance=d, prestrain=eps0)
        ss = SeamSolver(frame, info)
        R, L, EA, GJ, EIy, EIz, kGA = ss.cs.assembler.element_arrays()
        legs = np.asarray(info["legs"], bool)
        stitch = np.zeros(frame.n_elements, bool)
        stitch[int(info["fabric_elements"]):] = True
        f = 1e-3
        EAk = EA.copy()
        EAk[legs] *= f          # legs: force elements (constant tension), tiny stiffness
        ss.cs.set_stiffness(ss.cs.assembler.stiffness((R, L, EAk, GJ, EIy, EIz, kGA)))
        EAl = np.zeros_like(EA)
        EAl[stitch] = T / eps0   # pre-load EA eps0 = T in every stitch element
        ss.f_pre = prestrain_load(frame, EAl)
        try:
            ss.ramp(8, max_cuts=5)
            x, h = measure_profile(frame, info, ss.result.u)
            i0 = int(np.argmin(np.abs(x)))
            print(f"d = {d:g} mm, T = {T:g} N per leg: seam line {h[i0]:.2f} mm, crest {h.max():.2f} mm "
                  f"({time.time() - t:.1f} s)", flush=True)
            print("   h:", np.round(h, 2).tolist(), flush=True)
        except homtex.SolverError as e:
            print(f"d = {d:g} mm, T = {T:g} N per leg: failed ({e})", flush=True)
