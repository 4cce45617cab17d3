"""The charts (homtex.output.charts, charts_data): one unit per y axis, "quantity, unit" labels,
the cell in the title, seams at the effective seam distance, samples as scatter, labels that do
not overprint. Synthetic Datasets shaped like the stages' (fast; the stages themselves are run
in tests/test_cli.py)."""

import json

import numpy as np
import pytest
import xarray as xr

from homtex.output.charts import (
    LOAD_CELL_N,
    axis_units,
    compression_chart,
    cushions_chart,
    macro_chart,
    place_labels,
    pyplot,
    seam_profile_chart,
    speed_accuracy_chart,
)
from homtex.output.charts_data import chart, dataset_kind, generic_chart, study_chart

CELL = "my_cell"


def _meta(ds):
    for n in [*ds.data_vars, *ds.coords]:
        ds[n].attrs.setdefault("units", "1")
        ds[n].attrs.setdefault("long_name", str(n))
    ds.attrs["cell_name"] = CELL
    return ds


def compression_ds():
    e = np.linspace(0.02, 0.5, 25)
    s = 350 * e + 900 * np.maximum(e - 0.3, 0) ** 2
    ds = xr.Dataset({"stress": ("strain", s, {"units": "kPa", "long_name": "stress"}),
                     "force": ("strain", s * 0.0169, {"units": "N", "long_name": "force"}),
                     "plate_displacement": ("strain", 20 * e, {"units": "mm", "long_name": "plate displacement"}),
                     "active_contacts": ("strain", np.arange(25), {"units": "1", "long_name": "contacts"}),
                     "bending_z": ("strain", e ** 2, {"units": "N mm", "long_name": "bending energy"}),
                     "group_energy": (("strain", "group"), np.outer(e ** 2, [1, 2]),
                                      {"units": "N mm", "long_name": "energy by group"})},
                    coords={"strain": ("strain", e, {"units": "1", "long_name": "compression strain"}),
                            "group": ("group", ["pile", "pillar"], {"units": "1", "long_name": "group"})},
                    attrs={"thickness_mm": 20.0, "validity_strain": 0.3, "modulus_kPa": 350.0, "seconds": 12.3})
    return _meta(ds)


def yarn_profile_ds(d=25.4, n=12):
    """Like homtex.seam_profile(method="yarn"): n wale bins over one effective seam distance."""
    x = -d / 2 + d / n * np.arange(n)
    h = 20 - 4.3 * np.exp(-np.abs(x) / 2.6)
    ds = xr.Dataset({"height": ("x", h, {"units": "mm", "long_name": "cushion height"}),
                     "cushion_height": ((), h.max(), {"units": "mm", "long_name": "cushion height"}),
                     "seam_height": ((), h[np.argmin(np.abs(x))], {"units": "mm", "long_name": "seam line"}),
                     "prestrain": ((), 0.3, {"units": "1", "long_name": "pre-strain"}),
                     "seam_distance": ((), d, {"units": "mm", "long_name": "effective seam distance"})},
                    coords={"x": ("x", x, {"units": "mm", "long_name": "position across the seam"})},
                    attrs={"method": "yarn", "effective_seam_distance_mm": d, "requested_seam_distance_mm": 24.0,
                           "thickness_mm": 20.0, "homtex_kind": "seam_profile"})
    return _meta(ds)


def macro_ds(specimens=True):
    w = np.linspace(0, 10, 51)
    F = np.array([50 * w ** 2, 30 * np.maximum(w - 4, 0) ** 2])
    if not specimens:
        ds = xr.Dataset({"force": ("plate_displacement", F[1], {"units": "N", "long_name": "punch force"}),
                         "stress": ("plate_displacement", F[1] / 12.1, {"units": "kPa", "long_name": "stress"}),
                         "column_height": ("column_x", np.full(4, 16.0), {"units": "mm", "long_name": "height"})},
                        coords={"plate_displacement": ("plate_displacement", w, {"units": "mm", "long_name": "w"}),
                                "column_x": ("column_x", np.arange(4.0), {"units": "mm", "long_name": "x"})},
                        attrs={"thickness_mm": 20.0, "plate_area_mm2": 12100.0, "seam_distance_mm": 24.0})
        return _meta(ds)
    ds = xr.Dataset({"force": (("specimen", "plate_displacement"), F, {"units": "N", "long_name": "punch force"}),
                     "stress": (("specimen", "plate_displacement"), F / 12.1, {"units": "kPa", "long_name": "s"})},
                    coords={"specimen": ["no seams", "d=24"],
                            "plate_displacement": ("plate_displacement", w, {"units": "mm", "long_name": "w"})},
                    attrs={"thickness_mm": 20.0, "height_scatter_mm": 1.0})
    return _meta(ds)


def study_ds(layout):
    if layout == "grid":
        E, r = np.array([1000.0, 2000.0, 3000.0]), np.array([0.03, 0.04])
        ds = xr.Dataset({"E1": (("E", "r"), np.outer(E, r ** 2) * np.pi, {"units": "N/mm", "long_name": "E1"}),
                         "C": (("E", "r", "row"), np.ones((3, 2, 2)), {"units": "N/mm", "long_name": "C"}),
                         "status": (("E", "r"), np.zeros((3, 2), int), {"units": "1", "long_name": "status"})},
                        coords={"E": ("E", E, {"units": "MPa", "long_name": "modulus"}),
                                "r": ("r", r, {"units": "mm", "long_name": "radius"}), "row": ["11", "22"]})
        names = ["E", "r"]
    else:
        rng = np.random.default_rng(0)
        d, e = rng.uniform(12, 50, 16), rng.uniform(0.1, 0.7, 16)
        ds = xr.Dataset({"cushion_height": ("sample", 20 - 60 * e / d, {"units": "mm", "long_name": "cushion"}),
                         "stitch_force": ("sample", 3 * e, {"units": "N", "long_name": "stitch force"}),
                         "status": ("sample", np.zeros(16, int), {"units": "1", "long_name": "status"})},
                        coords={"sample": np.arange(16), "seam_distance": ("sample", d, {"units": "mm"}),
                                "prestrain": ("sample", e, {"units": "1"})})
        names = ["seam_distance", "prestrain"]
    ds.attrs.update(study_layout=layout, study_parameters=json.dumps(names), study_name="s", study_task="t",
                    points_total=ds.status.size, points_ok=ds.status.size, points_failed=0)
    return _meta(ds)


def speed_ds():
    t = np.array([0.43, 0.42, 0.89, 0.61, 0.13, 0.24, 2.2e-5, 21.5, 36.9, 18.6, 9e-4])
    e = np.array([0.14, 0.044, 0.021, 0.0095, 0.044, 0.0441, 0.0439, 0.0, 0.118, 0.054, 0.08])
    q = ["A unseamed"] * 7 + ["B seamed"] * 4
    ds = xr.Dataset({"seconds": ("model", t, {"units": "s", "long_name": "run time"}),
                     "error": ("model", e, {"units": "1", "long_name": "error"}),
                     "question": ("model", q, {"units": "1", "long_name": "question"})},
                    coords={"model": [f"model {i}" for i in range(len(t))]})
    return _meta(ds)


def cushions_ds():
    xi = np.linspace(-0.5, 0.5, 41)
    cases = ["d=18", "d=24", "d=43", "d=43, eps0=0.15"]
    d = np.array([18.0, 24.0, 43.0, 43.0])
    data = {"seam_distance": ("case", d, {"units": "mm", "long_name": "asked"})}
    for m, deff in (("yarn", [16.93, 25.4, 42.33, 42.33]), ("foundation", d)):
        data[f"height_{m}"] = (("case", "xi"), 20 - 4 * np.exp(-np.abs(np.outer(d, xi)) / 3), {"units": "mm"})
        data[f"cushion_height_{m}"] = ("case", [20.0, 20.0, 20.0, 20.0], {"units": "mm"})
        data[f"seam_height_{m}"] = ("case", [16.0] * 4, {"units": "mm"})
        data[f"prestrain_{m}"] = ("case", [0.3, 0.3, 0.3, 0.15], {"units": "1"})
        data[f"seam_distance_{m}"] = ("case", deff, {"units": "mm"})
    ds = xr.Dataset(data, coords={"case": cases, "xi": xi})
    ds.attrs["thickness_mm"] = 20.0
    return _meta(ds)


def seamed_ds():
    w = np.linspace(0, 6, 31)
    tr = np.linspace(0, 6, 201)
    ds = xr.Dataset({"stress_yarn": ("plate_displacement", 20 * w, {"units": "kPa"}),
                     "stress_macro": ("plate_displacement", 21 * w, {"units": "kPa"}),
                     "stress_macro_curve": ("travel", 21 * tr, {"units": "kPa"}),
                     "stress_unseamed_curve": ("travel", 30 * tr, {"units": "kPa"}),
                     "plate_contacts": ("plate_displacement", np.arange(31), {"units": "1"}),
                     "cushions_touched": ("plate_displacement", np.arange(31) // 3, {"units": "1"})},
                    coords={"plate_displacement": w, "travel": tr},
                    attrs={"seam_distance_mm": 24.0, "max_relative_error": 0.08, "max_relative_error_held": 0.16,
                           "max_relative_error_released": 0.08, "stitch_meets_punch_mm": 5.46, "thickness_mm": 20.0})
    return _meta(ds)


def strip_ds():
    """Like the strip check's file (homtex.seams.strip.strip_check)."""
    e = np.linspace(0.02, 0.5, 25)
    ramp = np.maximum(e - 0.25, 0.0)
    data = {f"stress_{k}": ("strain", f * 40 * ramp, {"units": "kPa", "long_name": k})
            for k, f in (("strip", 1.0), ("cushion_laws", 1.04), ("shifted_law", 1.01), ("columns", 0.8))}
    data.update({"cushion_height_strip": ("cushion", [14.9, 15.5], {"units": "mm", "long_name": "strip"}),
                 "cushion_height_single": ("cushion", [14.6, 15.3], {"units": "mm", "long_name": "single"}),
                 "prestrain": ("cushion", [0.64, 0.52], {"units": "1", "long_name": "eps0"})})
    ds = xr.Dataset(data, coords={"strain": ("strain", e, {"units": "1"}), "cushion": [0, 1]},
                    attrs={"seams": 2, "seam_distance_mm": 25.4, "error_cushion_laws": 0.04, "error_shifted_law": 0.01,
                           "error_columns": 0.2, "thickness_mm": 20.0})
    return _meta(ds)


def knit_tensile_ds():
    """Like the knit rib study's file (homtex.tensile over strain, friction as a dimension)."""
    e = np.linspace(0, 0.45, 10)
    f = np.outer([1.0, 1.6], 0.023 + 0.2 * e + 40 * np.maximum(e - 0.35, 0) ** 2)
    ds = xr.Dataset({"force_per_width": (("friction", "strain"), f, {"units": "N/mm", "long_name": "force per width"}),
                     "force": (("friction", "strain"), 1.046 * f, {"units": "N", "long_name": "force"}),
                     "width": (("friction", "strain"), np.tile(1.046 - e, (2, 1)), {"units": "mm", "long_name": "w"})},
                    coords={"strain": ("strain", e, {"units": "1", "long_name": "strain"}),
                            "friction": ("friction", [0.0, 0.5], {"units": "1", "long_name": "friction"})},
                    attrs={"direction": "wale", "specimen": "periodic cell"})
    return _meta(ds)


ALL = {"compression": compression_ds, "seam_profile": yarn_profile_ds, "macro_curves": macro_ds,
       "macro_curve": lambda: macro_ds(False), "study": lambda: study_ds("samples"), "cushions": cushions_ds,
       "seamed_vs_macro": seamed_ds, "speed_accuracy": speed_ds, "knit_tensile": knit_tensile_ds,
       "strip_vs_macro": strip_ds}


def _texts(fig):
    return " ".join([fig._suptitle.get_text() if fig._suptitle else ""] + [a.get_title() for a in fig.axes])


@pytest.mark.parametrize("kind", sorted(ALL))
def test_every_chart_has_one_unit_per_axis_labelled_and_names_the_cell(kind):
    ds = ALL[kind]()
    if kind != "study":
        ds.attrs["homtex_kind"] = kind
    assert dataset_kind(ds) == kind
    fig = chart(ds)
    drawn = 0
    for ax in fig.axes:
        units = axis_units(ax)
        assert len(units) <= 1, (kind, ax.get_title(), units)      # never two units on one axis
        if units:
            drawn += 1
            (u,) = units
            assert ax.get_ylabel().endswith(f", {u}"), (kind, ax.get_ylabel(), u)
            assert any(a.get_xlabel() for a in ax.get_shared_x_axes().get_siblings(ax)), (kind, ax.get_title())
    assert drawn >= 1
    assert CELL in _texts(fig)
    assert "s)" not in _texts(fig).replace("(samples", "")   # no run times in titles ("12.3 s)")
    pyplot().close(fig)


def test_the_kind_is_recognised_without_the_attribute():
    for kind, make in ALL.items():
        ds = make()
        ds.attrs.pop("homtex_kind", None)
        assert dataset_kind(ds) == kind, kind


def test_seams_are_drawn_at_the_effective_seam_distance_and_both_panels_share_the_y_range():
    """the yarn-level profile's x bins span 25.4 - 25.4/12 = 23.28 mm; the seams repeat every 25.4 mm"""
    ds = yarn_profile_ds(25.4, 12)
    fig = seam_profile_chart(ds, periods=3)
    ax = fig.axes[0]
    seams = sorted(ln.get_xdata()[0] for ln in ax.lines if ln.get_label().lstrip("_") == "seam line")
    assert len(seams) >= 3
    np.testing.assert_allclose(np.diff(seams), 25.4, rtol=1e-12)
    assert fig.axes[0].get_ylim() == fig.axes[1].get_ylim()
    # the drawn profile repeats with the same period: its outline at x and x + d agree
    poly = ax.collections[0].get_paths()[0].vertices
    assert poly[:, 0].max() - poly[:, 0].min() == pytest.approx(25.4)
    pyplot().close(fig)


def test_the_paper_measurements_are_on_the_cushion_chart():
    fig = cushions_chart(cushions_ds())
    ax = fig.axes[-1]
    labels = [ln.get_label() for ln in ax.lines] + [c.get_label() for c in ax.containers]
    assert any("measured" in s for s in labels) and any("paper's simulation" in s for s in labels)
    sim = next(ln for ln in ax.lines if ln.get_label() == "paper's simulation")
    np.testing.assert_allclose(sim.get_ydata(), [10.23, 14.33, 20.3])
    np.testing.assert_allclose(sim.get_xdata(), [18.4, 24.4, 43.4])   # beside the measured ones
    pyplot().close(fig)


def test_force_charts_draw_the_load_cell_and_shade_the_validity_range():
    """The load cell is drawn; a macro chart claims no validity range (the paper's curves are plots,
    nothing measured is on it); a linear curve shades its own measured validity."""
    fig = macro_chart(macro_ds())
    for ax in fig.axes[:2]:
        assert any(np.allclose(ln.get_ydata(), LOAD_CELL_N) for ln in ax.lines)
        assert not any("agree" in (p.get_label() or "") or "valid" in (p.get_label() or "") for p in ax.patches)
    assert fig.axes[1].get_ylim()[1] == pytest.approx(1.2 * LOAD_CELL_N)   # the load cell's range, zoomed
    pyplot().close(fig)
    fig = compression_chart(compression_ds())
    spans = [p for p in fig.axes[0].patches if "valid" in (p.get_label() or "")]
    assert spans and spans[0].get_x() == 0 and spans[0].get_width() == pytest.approx(30.0)
    pyplot().close(fig)


def test_speed_accuracy_labels_never_overprint_and_the_error_is_defined():
    ds = speed_ds()
    fig = speed_accuracy_chart(ds)
    ax = fig.axes[0]
    assert "max |stress - reference| / max |reference|" in ax.get_ylabel()
    numbers = [t for t in ax.texts if t.get_text().isdigit()]
    assert sorted(int(t.get_text()) for t in numbers) == list(range(1, ds.sizes["model"] + 1))
    fig.canvas.draw()
    boxes = [t.get_window_extent() for t in numbers]
    for i, a in enumerate(boxes):
        for b in boxes[i + 1:]:
            assert not a.overlaps(b), (a, b)
    pyplot().close(fig)


def test_place_labels_avoids_points_and_labels():
    plt = pyplot()
    fig, ax = plt.subplots()
    xy = np.array([[1.0, 1.0], [1.01, 1.0], [1.02, 1.01], [1.0, 1.02]])
    ax.plot(*xy.T, "o")
    ax.set(xlim=(0.9, 1.1), ylim=(0.9, 1.1))
    boxes = place_labels(ax, xy, ["10", "11", "12", "13"])
    for i, a in enumerate(boxes):
        for b in boxes[i + 1:]:
            assert not (a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3])
    plt.close(fig)


def test_samples_are_scatter_not_lines_and_grids_are_lines_or_heat_maps():
    fig = study_chart(study_ds("samples"), var="stitch_force")
    axes = [a for a in fig.axes if axis_units(a)]
    assert len(axes) == 2 and all(not a.lines and a.collections for a in axes)   # no line in sample order
    assert axis_units(axes[0]) == {"N"}
    pyplot().close(fig)
    fig = study_chart(study_ds("grid"))   # 2-D grid: heat map + lines of E1
    assert any(a.collections and type(a.collections[0]).__name__ == "QuadMesh" for a in fig.axes)
    assert any(len(a.lines) == 2 for a in fig.axes)
    pyplot().close(fig)
    fig = study_chart(study_ds("grid"), var="C", sel={"row": "22"})
    pyplot().close(fig)
    ds1 = study_ds("grid").isel(r=0).drop_vars("r")
    ds1.attrs["study_parameters"] = json.dumps(["E"])
    fig = study_chart(ds1)
    (ax,) = [a for a in fig.axes if axis_units(a)]
    assert len(ax.lines) == 1 and axis_units(ax) == {"N/mm"}
    pyplot().close(fig)


def test_study_chart_names_what_is_missing():
    from homtex.errors import InputError

    with pytest.raises(InputError, match="--sel"):
        study_chart(study_ds("grid"), var="C")
    with pytest.raises(InputError, match="no such variable"):
        study_chart(study_ds("grid"), var="nope")
    with pytest.raises(InputError, match="no value"):
        study_chart(study_ds("grid"), var="C", sel={"row": "33"})


def test_generic_chart_puts_each_unit_on_its_own_axis():
    """force (N), stress (kPa), height (mm) and a count over one dimension: four panels (the old
    `homtex plot` drew them on one unlabelled axis)."""
    t = np.linspace(0, 1, 5)
    ds = _meta(xr.Dataset({"force": ("t", t, {"units": "N"}), "stress": ("t", 2 * t, {"units": "kPa"}),
                           "height": ("t", 3 * t, {"units": "mm"}), "n": ("t", np.arange(5), {"units": "1"}),
                           "force2": ("t", t ** 2, {"units": "N"})},
                          coords={"t": ("t", t, {"units": "s", "long_name": "time"})}))
    fig = generic_chart(ds)
    units = [axis_units(a) for a in fig.axes]
    assert sorted(u.pop() for u in units) == ["1", "N", "kPa", "mm"]
    for ax in fig.axes:
        assert ax.get_xlabel() == "time, s"
    pyplot().close(fig)
