"""Planning one patient's repair (SPEC §9): inputs, the reach bound, the template, the report.

Expected numbers are worked out here from the SPEC's formulas: the SPEC §1 leaflet (free
edge π/3·20 mm, height 20·sin²(π/6)/tan 34° + 5 mm), the Fung law of SPEC §3 written out
by hand, a graft W/H as the measured leaflet scaled by (1 + W, 1 + H).  The study behind
a plan is a stand-in case function where a real solve adds nothing.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import xml.etree.ElementTree as ET
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from valve_dolfinx._compat import MPI
from valve_dolfinx.exceptions import OutputConflictError, ParameterError
from valve_dolfinx.geometry.outline import GraftSize
from valve_dolfinx.plan.patient import (
    FIELDS,
    PatientInput,
    patient_from_mapping,
    patient_toml,
    read_patient,
    write_patient,
)
from valve_dolfinx.plan.reach import (
    free_edge_reach,
    free_edge_strains,
    largest_root_mm,
    max_fibre_stretch,
)
from valve_dolfinx.plan.recommendation import PlanAnswers, PlanRecommendation
from valve_dolfinx.sizing import MemberTable, Recommendation, Resolution, SizingAnswer
from valve_dolfinx.sizing.surface import ROOT_KEY

ROOT = Path(__file__).resolve().parents[1]
FREE_EDGE_MM = math.pi / 3 * 20.0
HEIGHT_MM = 20.0 * 0.25 / math.tan(math.radians(34.0)) + 5.0
KPA_80 = 80 * 0.133322
#: SPEC §3: native leaflet (Billiar & Sacks 2000), thickness 0.5 mm
C, A1, A2, A3 = 9.7, 49.56, 5.29, -3.12
THICKNESS = 0.5


# --- the patient's inputs --------------------------------------------------------------------
def test_defaults_are_the_spec_leaflet_exactly():
    patient = PatientInput(root_diameter_mm=21.0)
    assert patient.leaflet_free_edge_mm == pytest.approx(FREE_EDGE_MM, rel=1e-15)
    assert patient.leaflet_height_mm == pytest.approx(HEIGHT_MM, rel=1e-15)
    shape = patient.native_shape
    assert (shape.root_diameter, shape.gamma_deg, shape.commissure_height) == (20.0, 34.0, 5.0)
    assert patient.root_diameters_mm == (20.0, 21.0, 22.0)
    assert PatientInput(root_diameter_mm=21.0, root_uncertainty_mm=0.0).root_diameters_mm == (
        21.0,)


@pytest.mark.parametrize("patient", [
    PatientInput(root_diameter_mm=22.0),
    PatientInput(root_diameter_mm=23.4, root_uncertainty_mm=0.7, leaflet_free_edge_mm=22.1,
                 leaflet_height_mm=13.3, pressure_mmhg=90.0, graft_widths_pct=(0, 7.5),
                 graft_heights_pct=(13,), target_coaptation_mm=2.5,
                 graft_fibre_angle_deg=-15.0, paths=3, label='plan "7" ± 1'),
])
def test_patient_file_round_trip(tmp_path, patient):
    path = write_patient(tmp_path / "patient.toml", patient)
    assert read_patient(path) == patient
    text = path.read_text()
    for key in FIELDS:  # every key is in the file, with its unit where it has one
        assert key in text
    assert "root_diameter_mm = " in text and "# mm;" in text


def test_the_default_leaflet_gives_the_default_mesh_exactly():
    """A plan without a measured leaflet (or with the SPEC §1 leaflet's exact dimensions)
    builds the valve of the default geometry: same points, cells and flat coordinates."""
    from valve_dolfinx.geometry.valve import DEFAULT_MESH_SIZE, build_valve
    from valve_dolfinx.plan.runner import plan_study_settings

    patient = PatientInput(root_diameter_mm=20.0, leaflet_free_edge_mm=FREE_EDGE_MM,
                           leaflet_height_mm=HEIGHT_MM)
    layout = plan_study_settings(patient).layout()
    config = layout.configs["normal__root.loaded_diameter_mm=20"]
    assert config.geometry.mesh_size == DEFAULT_MESH_SIZE
    planned, default = build_valve(config.geometry), build_valve()
    for name in ("points", "cells", "flat", "fibres", "edges"):
        assert np.array_equal(getattr(planned, name), getattr(default, name)), name
    assert config.root.loaded_diameter == 20.0


def test_a_longer_free_edge_gives_a_proportionally_larger_wrap_diameter():
    base = PatientInput(root_diameter_mm=22.0, leaflet_free_edge_mm=20.0, leaflet_height_mm=12.0)
    longer = PatientInput(root_diameter_mm=22.0, leaflet_free_edge_mm=22.0,
                          leaflet_height_mm=12.0)
    assert longer.wrap_diameter_mm / base.wrap_diameter_mm == pytest.approx(1.1, rel=1e-13)
    assert base.wrap_diameter_mm == pytest.approx(3 * 20.0 / math.pi, rel=1e-13)


@pytest.mark.parametrize("key,value,bound", [
    ("root_diameter_mm", 15.9, "[16, 35]"), ("root_diameter_mm", 2.2, "[16, 35]"),
    ("root_diameter_mm", 220.0, "[16, 35]"), ("root_uncertainty_mm", -0.5, "[0, 3]"),
    ("root_uncertainty_mm", 5.0, "[0, 3]"), ("leaflet_free_edge_mm", 14.0, "[15, 50]"),
    ("leaflet_free_edge_mm", 60.0, "[15, 50]"), ("leaflet_height_mm", 9.0, "[10, 30]"),
    ("leaflet_height_mm", 31.0, "[10, 30]"), ("pressure_mmhg", 10.0, "[40, 120]"),
    ("pressure_mmhg", 200.0, "[40, 120]"), ("target_coaptation_mm", 0.0, "(0, 10]"),
    ("target_coaptation_mm", 12.0, "(0, 10]"), ("graft_fibre_angle_deg", 120.0, "[-90, 90]"),
    ("root_diameter_mm", float("nan"), "[16, 35]"),
])
def test_every_input_out_of_range_is_named(key, value, bound):
    data = {"root_diameter_mm": 22.0, key: value}
    if key.startswith("leaflet"):
        data.setdefault("leaflet_free_edge_mm", 22.0)
        data.setdefault("leaflet_height_mm", 13.0)
    with pytest.raises(ParameterError) as err:
        patient_from_mapping(data, source="PATIENT.toml")
    message = str(err.value)
    assert message.startswith("PATIENT.toml: ") and key in message and bound in message
    assert FIELDS[key].flag in message


@pytest.mark.parametrize("data,expected", [
    ({}, "root_diameter_mm is missing"),
    ({"root_diameter": 22.0}, "root_diameter_mm (mm)"),
    ({"root_diameter_mm": 22.0, "leaflet_height": 13.0}, "leaflet_height_mm (mm)"),
    ({"root_diameter_mm": "22 mm"}, "is not a number"),
    ({"root_diameter_mm": True}, "is not a number"),
    ({"root_diameter_mm": 22.0, "pressure_mmhg": "80"}, "is not a number"),
    ({"root_diameter_mm": 22.0, "leaflet_free_edge_mm": 22.0}, "needs leaflet_height_mm"),
    ({"root_diameter_mm": 22.0, "graft_widths_pct": [0, 7, 7]}, "given twice"),
    ({"root_diameter_mm": 22.0, "graft_heights_pct": ["x"]}, "not a number"),
    ({"root_diameter_mm": 22.0, "label": "two\nlines"}, "printable characters"),
    ({"root_diameter_mm": 22.0, "colour": "red"}, "allowed keys are"),
])
def test_bad_patient_data_gives_a_named_error(data, expected):
    with pytest.raises(ParameterError, match=None) as err:
        patient_from_mapping(data)
    assert expected in str(err.value)


def test_a_patient_file_that_is_not_toml_or_missing(tmp_path):
    from valve_dolfinx.exceptions import ConfigurationError, InputFileError

    with pytest.raises(InputFileError):
        read_patient(tmp_path / "absent.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("root_diameter_mm = = 22\n")
    with pytest.raises(ConfigurationError, match="not valid TOML"):
        read_patient(bad)


# --- can the leaflets close the root at all? ------------------------------------------------
def _pk2(e11: float, e22: float) -> tuple[float, float]:
    """SPEC §3 by hand, E12 = 0: S11 = c e^Q (A1 E11 + A3 E22), S22 = c e^Q (A2 E22 + A3 E11)."""
    g = C * math.exp(A1 * e11**2 + A2 * e22**2 + 2 * A3 * e11 * e22)
    return g * (A1 * e11 + A3 * e22), g * (A2 * e22 + A3 * e11)


def _cauchy_tensions(e11: float, e22: float) -> tuple[float, float]:
    """Membrane tension per current length: T_i = t·λ_i·S_i/λ_j."""
    s11, s22 = _pk2(e11, e22)
    l1, l2 = math.sqrt(1 + 2 * e11), math.sqrt(1 + 2 * e22)
    return THICKNESS * l1 * s11 / l2, THICKNESS * l2 * s22 / l1


def _strains_at(t1: float, t2: float) -> tuple[float, float]:
    from scipy.optimize import fsolve

    for start in ((0.05, 0.2), (0.05, 0.03), (0.1, 0.5)):
        sol, _, ok, msg = fsolve(lambda e: np.subtract(_cauchy_tensions(*e), (t1, t2)),
                                 start, xtol=1e-13, full_output=True)
        if ok == 1:
            return float(sol[0]), float(sol[1])
    raise AssertionError(f"no strain state with tensions {t1:g}, {t2:g} mN/mm: {msg}")


def test_the_hand_written_law_gives_the_spec_worked_numbers():
    """The law written out here reproduces SPEC §3: E11 = 0.0301, E22 = 0.1884 at equal
    second Piola-Kirchhoff stresses of 10.67 kPa (so the checks below rest on it)."""
    from scipy.optimize import fsolve

    e = fsolve(lambda e: np.subtract(_pk2(*e), 10.67), (0.03, 0.2), xtol=1e-13)
    assert e == pytest.approx((0.0301, 0.1884), abs=1e-4)


@pytest.mark.parametrize("tension", [5.0, 50.0, 213.3, 400.0])
def test_free_edge_strains_satisfy_the_fung_law(tension):
    """Tension ``tension`` along the free edge and none across it, by the law written out
    here (a free edge carries no load across itself)."""
    e11, e22 = free_edge_strains(_native(), tension)
    assert _cauchy_tensions(e11, e22) == pytest.approx((tension, 0.0), rel=1e-9, abs=1e-9)
    assert 0 < e22 < e11  # the fibres stretch; the leaflet extends across them too (A3 < 0)


def test_the_stretch_bound_is_the_free_edge_at_the_largest_tension():
    """Along the free edge (no tension across it) the fibre stretch grows with the tension,
    so none up to p·D exceeds the bound, which the bound reaches at p·D."""
    d = 22.0
    bound = max_fibre_stretch(KPA_80, d)
    stretches = [math.sqrt(1 + 2 * _strains_at(t, 0.0)[0])
                 for t in np.linspace(0.05, 1.0, 12) * KPA_80 * d]
    assert np.all(np.diff(stretches) > 0)
    assert stretches[-1] == pytest.approx(bound, rel=1e-9)
    assert 1.1 < bound < 1.25


def test_the_largest_root_is_where_the_reach_meets_the_diameter():
    d_max = largest_root_mm(FREE_EDGE_MM, KPA_80)
    e11, _ = _strains_at(KPA_80 * d_max, 0.0)
    assert FREE_EDGE_MM * math.sqrt(1 + 2 * e11) == pytest.approx(d_max, rel=1e-9)
    assert 23.0 < d_max < 26.0  # a stretch of 1.10-1.24 at most
    assert free_edge_reach(FREE_EDGE_MM, d_max * (1 - 1e-6), 80.0).can_seal
    assert not free_edge_reach(FREE_EDGE_MM, d_max * (1 + 1e-6), 80.0).can_seal


def test_cannot_seal_is_one_line_with_its_numbers():
    reach = free_edge_reach(18.0, 23.0, 80.0)
    assert not reach.can_seal and reach.reach_mm < 23.0
    line = reach.sentence()
    assert "\n" not in line and "cannot seal this 23.0 mm root whatever the graft" in line
    assert f"{reach.reach_mm:.1f} mm" in line and f"{reach.largest_root_mm:.1f} mm" in line
    assert free_edge_reach(FREE_EDGE_MM, 20.0, 80.0).can_seal  # the SPEC's valve closes


def _native():
    from valve_dolfinx.materials import NATIVE_LEAFLET

    return NATIVE_LEAFLET


# --- the graft template ----------------------------------------------------------------------
SVG = "{http://www.w3.org/2000/svg}"


def _path_points(element) -> np.ndarray:
    tokens = element.attrib["d"].replace("M", " ").replace("L", " ").replace("Z", " ").split()
    return np.array(tokens, dtype=float).reshape(-1, 2)


@pytest.fixture(scope="module")
def template(tmp_path_factory):
    """The W21/H27 template of a 22 mm × 13 mm leaflet, its files and the expected sizes."""
    from valve_dolfinx.geometry.template import GraftTemplate
    from valve_dolfinx.plan.template import write_template
    from valve_dolfinx.plotting.template import template_drawing

    patient = PatientInput(root_diameter_mm=22.0, leaflet_free_edge_mm=22.0,
                           leaflet_height_mm=13.0, label="test")
    drawn = GraftTemplate(patient.native_shape, GraftSize(21.0, 27.0), label="test")
    files = write_template(drawn, tmp_path_factory.mktemp("template"))
    graft_width, graft_height = 22.0 * 1.21, 13.0 * 1.27
    return {"files": files, "page": template_drawing(drawn), "template": drawn,
            "cut": (graft_width + 2.0, graft_height + 1.0)}


def test_template_svg_is_in_millimetres_at_true_size(template):
    root = ET.parse(template["files"].svg).getroot()
    assert (root.attrib["width"], root.attrib["height"]) == ("210mm", "297mm")
    assert root.attrib["viewBox"] == "0 0 210 297"
    paths = {p.attrib.get("id"): p for p in root.iter(f"{SVG}path")}
    cut = _path_points(paths["cut-line"])
    assert np.ptp(cut, axis=0) == pytest.approx(template["cut"], abs=1e-6)
    bar = _path_points(paths["calibration-bar"])
    assert np.ptp(bar[:, 0]) == pytest.approx(50.0, abs=1e-9)
    free = _path_points(paths["free-edge"])
    assert np.ptp(free[:, 0]) == pytest.approx(22.0 * 1.21, abs=1e-9)
    texts = " ".join(t.text for t in root.iter(f"{SVG}text"))
    assert "free edge 26.6 mm" in texts and "height 16.5 mm" in texts and "test" in texts


def test_the_margin_is_one_millimetre_along_the_attachment_and_none_on_the_free_edge(template):
    t = template["template"]
    s = t.shape
    cut, attachment = t.cut_line(), t.attachment()
    top = s.height
    # the free edge is part of the cut line: no margin beyond it
    assert cut[:, 1].max() == pytest.approx(top, abs=1e-12)
    edge = [i for i in range(len(cut) - 1)
            if np.allclose(cut[i], [s.half_width, top]) and np.allclose(cut[i + 1],
                                                                        [-s.half_width, top])]
    assert len(edge) == 1
    # every other point of the cut line lies 1 mm from the attachment edge
    a, b = attachment[:-1], attachment[1:]
    below = cut[cut[:, 1] < top - 1e-9]
    ab = b - a
    t_ = np.clip(np.einsum("pij,ij->pi", below[:, None, :] - a, ab)
                 / np.einsum("ij,ij->i", ab, ab), 0.0, 1.0)
    closest = a + t_[..., None] * ab
    distance = np.linalg.norm(below[:, None, :] - closest, axis=2).min(axis=1)
    assert len(below) > 200
    assert distance == pytest.approx(np.full(len(below), 1.0), abs=2e-3)


def _raster(pdf: Path, dpi: int = 300) -> np.ndarray:
    pdfium = pytest.importorskip("pypdfium2")
    document = pdfium.PdfDocument(str(pdf))
    try:
        assert len(document) == 1
        width, height = document[0].get_size()
        assert (width, height) == pytest.approx((210 / 25.4 * 72, 297 / 25.4 * 72), abs=0.01)
        image = document[0].render(scale=dpi / 72).to_pil().convert("L")
    finally:
        document.close()
    return np.asarray(image)


def _ink_extent(gray: np.ndarray, box: tuple[float, float, float, float], dpi: int = 300
                ) -> tuple[float, float]:
    """Width and height (mm) of the ink inside the page box (mm, y up)."""
    px = dpi / 25.4
    x0, y0, x1, y1 = box
    rows = slice(int((297 - y1) * px), int(math.ceil((297 - y0) * px)))
    cols = slice(int(x0 * px), int(math.ceil(x1 * px)))
    ink = gray[rows, cols] < 160
    ys, xs = np.nonzero(ink)
    return (xs.max() - xs.min() + 1) / px, (ys.max() - ys.min() + 1) / px


def test_template_pdf_printed_at_100_percent_measures_what_it_says(template):
    """Rasterised at 300 dpi, the cut piece and the calibration bar have their size in mm."""
    from valve_dolfinx.plotting.template import CUT_WIDTH_MM, FREE_EDGE_WIDTH_MM

    gray = _raster(template["files"].pdf)
    page = template["page"]
    x0, y0, x1, y1 = page.regions["cut"]
    width, height = _ink_extent(gray, (x0 - 1.5, y0 - 1.5, x1 + 1.5, y1 + 1.5))
    # the ink reaches half a line width beyond the lines' centres
    assert width - CUT_WIDTH_MM == pytest.approx(template["cut"][0], abs=0.3)
    assert height - 0.5 * (CUT_WIDTH_MM + FREE_EDGE_WIDTH_MM) == pytest.approx(
        template["cut"][1], abs=0.3)
    bx0, by0, bx1, by1 = page.regions["calibration"]
    bar, _ = _ink_extent(gray, (bx0 - 2.0, by0 + 1.0, bx1 + 2.0, by1 - 1.0))
    assert bar == pytest.approx(50.0, abs=0.3)


def test_graft_size_parse():
    assert GraftSize.parse("14/13") == GraftSize(14.0, 13.0)
    assert GraftSize.parse("W21/H27").stem == "W21_H27"
    for bad in ("14", "a/b", "-5/10", "14/200"):
        with pytest.raises(ParameterError, match="--template"):
            GraftSize.parse(bad)


# --- the one-page report ---------------------------------------------------------------------
def _pdf_text(path: Path) -> str:
    pdfium = pytest.importorskip("pypdfium2")
    document = pdfium.PdfDocument(str(path))
    try:
        assert len(document) == 1
        return " ".join(document[0].get_textpage().get_text_range().split())
    finally:
        document.close()


def answer(graft=None, margin=None, closest=None, shortfall=None, limiting=None,
           target=2.31, source="given", members=("",), trim=None, tables=()
           ) -> PlanRecommendation:
    """A plan's answer made by hand: the recommendation of a study over ``members`` (the
    members named by themselves), its answer ``graft`` with ``margin``, or ``closest`` with
    ``shortfall``."""
    resolution = Resolution(None, 0, None, None, "not measured")
    targets = dict.fromkeys(members, target)
    size = GraftSize(*graft) if graft else None
    sizing = SizingAnswer({}, list(members), targets, source, resolution, size=size,
                          margin_mm=margin, limiting_member=limiting,
                          highest=GraftSize(*closest) if closest else size,
                          shortfall_mm=shortfall, why="" if size else "short", trim=trim)
    study = Recommendation({}, list(members), targets, target, source, sizing,
                           tables=list(tables))
    return PlanRecommendation(study, {}, source)


ANSWERS = {
    "graft": (answer((14, 13), 0.12, limiting="root 23.0 mm, billowed placement",
                     source="the normal valve's",
                     members=("root 21.0 mm", "root 22.0 mm", "root 23.0 mm")),
              ["Recommended graft W14/H13", "smallest margin is 0.12 mm",
               "root 23.0 mm, billowed placement", "in all 3 members"]),
    # a margin that rounds to 0.00 mm is shown with its significant digits
    "thin margin": (answer((27, 27), 0.0023, limiting="root 23.0 mm",
                           source="the normal valve's", members=("root 22.0 mm", "root 23.0 mm")),
                    ["Recommended graft W27/H27", "smallest margin is 0.0023 mm, in root 23.0",
                     "Smallest margin over the target: 0.0023 mm, in root 23.0 mm."]),
    # the answer cut half a millimetre off: the page says it is not robust to it
    # ... and names its members, every root along every path, in one line
    "cut": (answer((10, 19), -0.14, limiting="root 20.0 mm",
                   members=tuple(f"root {d:.1f} mm, path {p}" for d in (20.0, 21.0)
                                 for p in (1, 2)),
                   tables=[MemberTable(f"root {d:.1f} mm, path {p}", [],
                                       uncertain=((ROOT_KEY, d),), path=p)
                           for d in (20.0, 21.0) for p in (1, 2)],
                   trim={"mm": 0.5, "width_pct": 2.0, "height_pct": 4.0,
                         "sizes": ["W8/H15", "W8/H19", "W8/H23", "W10/H15", "W10/H23",
                                   "W12/H15", "W12/H19", "W12/H23"],
                         "worst_margin_mm": -0.54, "worst_margin_size": "W8/H15",
                         "seal_probability": 0.77, "seal_size": "W8/H15",
                         "failing": ["W8/H15", "W8/H19"], "robust": False}),
            ["Cut 0.5 mm off its template", "2 of the 8 such sizes do not qualify (W8/H15, "
             "W8/H19)", "least margin -0.54 mm (W8/H15), least sealing 0.77 (W8/H15)",
             "not robust to the cut",
             "Members (each solved on its own): roots 20.0, 21.0 mm × paths 1, 2 (4)."]),
    "closest": (answer(closest=(27, 40), shortfall=0.4, target=2.3, members=("a", "b")),
                ["No graft in the studied range is robust", "The closest is W27/H40",
                 "0.40 mm short"]),
    "cannot": (PlanRecommendation(cannot_seal=free_edge_reach(16.0, 22.0, 80.0).sentence()),
               ["cannot seal this 22.0 mm root whatever the graft", "Nothing was computed"]),
}


@pytest.mark.parametrize("kind", ANSWERS)
def test_the_report_is_one_a4_page_with_the_answer(tmp_path, kind):
    from valve_dolfinx.plan.report import PlanFigures, RunInfo, write_plan_report

    rec, words = ANSWERS[kind]
    patient = PatientInput(root_diameter_mm=22.0, label="report test")
    md, pdf = write_plan_report(tmp_path, patient, PlanAnswers((rec,)), [PlanFigures()],
                                RunInfo(), "only a test",
                                free_edge_reach(FREE_EDGE_MM, 22.0, 80.0))
    text = _pdf_text(pdf)
    markdown = md.read_text()
    for word in [*words, "Repair plan: report test", "22.0 ± 1.0 mm", "only a test"]:
        if word != "Nothing was computed":
            assert word in markdown, word
        assert word in text, word
    if kind != "cannot":
        assert "not made" in text  # the pictures that were not given say so


@pytest.mark.parametrize(("margin", "shown"), [(0.12, "0.12"), (0.0051, "0.01"),
                                               (0.0023, "0.0023"), (0.0004, "0.00040"),
                                               (0.0, "0.00")])
def test_the_margin_is_shown_with_its_significant_digits(margin, shown):
    rec = answer((14, 13), margin)
    assert f"its smallest margin is {shown} mm." in rec.headline()


# --- the plan, end to end on a stand-in study ---------------------------------------------
#: the stand-in's normal valve at a 22 mm root (mm)
NORMAL_MM = 2.0


def path_number(config, start: Path | None) -> int:
    """The study's numerical path of a graft's case: the path that starts from another
    case's state if it has a start, else the most specific of the other paths whose
    settings it holds."""
    from valve_dolfinx.config import get_dotted
    from valve_dolfinx.study.paths import PATHS

    if start is not None:
        return next(p.number for p in PATHS if p.start is not None)
    data = config.to_dict()
    held = [p for p in PATHS if p.start is None
            and all(get_dotted(data, k) == v for k, v in p.overrides.items())]
    return max(held, key=lambda p: len(p.overrides)).number


def stand_in_height(size, diameter: float, path: int) -> float:
    """The stand-in's minimum coaptation height: the normal valve loses 0.2 mm per mm of
    root; a graft is the plane 0.605 + 0.1 W + 0.005 H (mm, W and H in per cent) at a
    22 mm root, loses 0.25 mm per mm of root and 0.1 mm per path after the first."""
    if size is None:
        return NORMAL_MM - 0.2 * (diameter - 22.0)
    w, h = size
    return 0.605 + 0.1 * w + 0.005 * h - 0.25 * (diameter - 22.0) - 0.1 * (path - 1)


def surface_margin(size, diameter: float, target: float | None = None) -> float:
    """What the surface reads: the paths' mean (0.05 mm below path 1) minus the target."""
    return (margin(size, diameter, 1, target) + margin(size, diameter, 2, target)) / 2


#: the paths differ by 0.1 mm in every cell: their pooled standard deviation, the tolerance
PATH_SCATTER_MM = 0.1 / 2**0.5


def margin(size, diameter: float, path: int, target: float | None = None) -> float:
    """A graft's height minus its member's target (the normal valve's, or ``target``)."""
    reference = stand_in_height(None, diameter, 1) if target is None else target
    return stand_in_height(size, diameter, path) - reference


def stand_in_case(config, out_dir: Path, comm, *, start: Path | None = None) -> dict:
    """A case result of :func:`stand_in_height`, with the two closed-valve pictures a case
    writes, each of a grey level of its own (the case's index in ``_SHADES``)."""
    import matplotlib.image

    g = config.geometry
    key = None if g.graft_width_pct is None else (g.graft_width_pct, g.graft_height_pct)
    d = config.root.loaded_diameter
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    for name in ("closed_valve_aortic.png", "closed_valve_ventricular.png"):
        matplotlib.image.imsave(out_dir / name, np.full((8, 8), 0.5), cmap="gray")
    return {"graft_width_pct": g.graft_width_pct, "graft_height_pct": g.graft_height_pct,
            "converged": True, "competent": True,
            "min_coaptation_height_mm": stand_in_height(key, d, path_number(config, start)),
            "regurgitant_orifice_area_mm2": 0.0, "root_diameter_mm": d,
            "mesh_size_mm": g.mesh_size, "n_ranks": comm.size, "wall_time_s": 0.01,
            "parameters": config.to_dict(), "versions": {"valve_dolfinx": "test"}}


def no_case(*args, **kwargs):
    raise AssertionError("a case was computed")


def _patient(**changes) -> PatientInput:
    data = dict(root_diameter_mm=22.0, leaflet_free_edge_mm=22.0, leaflet_height_mm=13.0,
                graft_widths_pct=(7.0, 14.0), graft_heights_pct=(13.0, 27.0), label="stand-in",
                design="grid")  # these tests count the grid's cases; tests/test_adaptive.py
    # tests the adaptive design
    return PatientInput(**{**data, **changes})


def _words(diameter: float, path: int) -> str:
    from valve_dolfinx.study.paths import PATHS

    return f"root {diameter:.1f} mm, {PATHS[path - 1].label}"


def _case_names(plan: Path) -> list[str]:
    return sorted(p.name for p in (plan / "study" / "cases").iterdir()
                  if p.is_dir() and not p.name.startswith("."))


def _plan_files(out: Path) -> dict[str, bytes]:
    names = ("plan.md", "plan.pdf", "summary.json", "template_W14_H13.svg",
             "template_W14_H13.pdf", "template_W14_H13.png", "template_W21_H27.pdf")
    return {name: (out / name).read_bytes() for name in names}


def test_a_plan_recommends_over_three_diameters_and_the_paths(tmp_path):
    """D ± U = 21, 22, 23 mm and two paths: six members, the normal valve once per diameter
    and its height each member's target.  The surface reads the paths' mean, worst at
    23 mm: W14/H13 is 0.03 mm short there (:func:`surface_margin`), within the paths'
    scatter of 0.071 mm, so it qualifies; every size of smaller (or equal) flat area is
    narrower and at least 0.1 - 0.005 mm lower, beyond it (W13/H14: -0.125 mm): the
    answer is W14/H13, on the grid."""
    from valve_dolfinx.plan.runner import run_plan

    patient = _patient()
    assert patient.paths == 2
    out = tmp_path / "plan"
    outcome = run_plan(patient, out, MPI.COMM_SELF, mesh_size_mm=2.0,
                       templates=[GraftSize(21, 27)], case_function=stand_in_case)
    rec = outcome.answers.values[0]
    study, answer = rec.recommendation, rec.recommendation.answer
    members = [(d, p) for d in (21.0, 22.0, 23.0) for p in (1, 2)]
    assert [rec.name(m) for m in study.members] == [_words(d, p) for d, p in members]
    assert {rec.name(m): t for m, t in study.targets_mm.items()} == {
        _words(d, p): pytest.approx(stand_in_height(None, d, 1)) for d, p in members}
    assert study.target_mm is None
    assert rec.target_source == "the normal valve's at the same root"
    expected = surface_margin((14.0, 13.0), 23.0)
    assert expected == pytest.approx(-0.03) and -PATH_SCATTER_MM < expected
    assert surface_margin((13.0, 14.0), 23.0) < -PATH_SCATTER_MM
    assert rec.graft == GraftSize(14.0, 13.0)
    assert answer.margin_mm == pytest.approx(expected, abs=0.02)
    assert rec.name(answer.limiting_member) == "root 23.0 mm"
    assert [c.qualifies for c in study.cells] == [False, False, False, False]  # as solved
    assert study.cells[2].size == GraftSize(14.0, 13.0)
    assert study.cells[2].spread_mm == pytest.approx(
        stand_in_height((14.0, 13.0), 21.0, 1) - stand_in_height((14.0, 13.0), 23.0, 2))
    names = _case_names(out)
    assert len(names) == 3 + 4 * 3 * 2 and "normal__root.loaded_diameter_mm=23" in names
    assert "W14_H13__root.loaded_diameter_mm=23__path=2" in names

    summary = json.loads((out / "summary.json").read_text())
    saved = summary["answers"]["values"][0]
    assert saved["graft"]["label"] == "W14/H13"
    assert saved["margin_mm"] == answer.margin_mm
    assert saved["limiting_member"] == "root 23.0 mm" and len(saved["members"]) == 6
    assert summary["reach"]["can_seal"] is True and summary["patient"]["paths"] == 2
    assert summary["run"]["cases"] == 27 and summary["run"]["converged"] == 27
    assert summary["run"]["wall_time_s"] == pytest.approx(27 * 0.01)
    assert summary["run"]["mesh_size_mm"] == 2.0
    dims = {t["graft"]: t for t in summary["templates"]}
    assert set(dims) == {"W14/H13", "W21/H27"}
    assert dims["W14/H13"]["free_edge_mm"] == pytest.approx(22.0 * 1.14, rel=1e-12)
    assert dims["W14/H13"]["height_mm"] == pytest.approx(13.0 * 1.13, rel=1e-12)
    assert dims["W14/H13"]["cut_width_mm"] == pytest.approx(22.0 * 1.14 + 2.0, rel=1e-12)
    assert dims["W14/H13"]["cut_height_mm"] == pytest.approx(13.0 * 1.13 + 1.0, rel=1e-12)
    for name in ("template_W14_H13.svg", "template_W21_H27.svg", "study/sizing_map.png"):
        assert (out / name).is_file(), name
    # patient.toml keeps the mesh the plan ran with, so that rerunning it recomputes nothing
    assert read_patient(out / "patient.toml") == replace(patient, mesh_size_mm=2.0)
    # the closed valve shown is the recommended graft's at the measured diameter, path 1
    markdown = (out / "plan.md").read_text()
    assert "(study/cases/W14_H13__root.loaded_diameter_mm=22/closed_valve_aortic.png)" in markdown
    assert "(study/cases/W14_H13__root.loaded_diameter_mm=22/closed_valve_ventricular.png)" in (
        markdown)
    assert f"| W14/H13 | {stand_in_height((14.0, 13.0), 23.0, 2):.2f} |" in markdown
    text = _pdf_text(out / "plan.pdf")
    assert "in all 6 members within the model's resolution" in rec.headline()
    for words in ("Recommended graft W14/H13", "in all 6 members", "root 23.0 mm",
                  "worst case of each graft over its 6 members"):
        assert words in text, words


def test_a_rerun_resumes_and_report_rebuilds_the_plan(tmp_path, capsys, quiet_cli):
    """A rerun with the same inputs computes nothing and writes the same plan; `report DIR`
    rebuilds plan.md, plan.pdf, the templates and summary.json from the case folders (the
    templates already in the folder among them); another patient in the folder is refused."""
    from valve_dolfinx.cli import main
    from valve_dolfinx.plan.runner import run_plan

    patient, out = _patient(), tmp_path / "plan"
    run_plan(patient, out, MPI.COMM_SELF, mesh_size_mm=2.0, templates=[GraftSize(21, 27)],
             case_function=stand_in_case)
    summary = json.loads((out / "summary.json").read_text())
    run_plan(patient, out, MPI.COMM_SELF, mesh_size_mm=2.0, case_function=no_case)
    assert json.loads((out / "summary.json").read_text()) == summary
    written = _plan_files(out)
    for name in written:
        if name != "template_W21_H27.svg":
            (out / name).unlink()
    (out / "study" / "sizing_map.png").unlink()
    assert main(["report", str(out)]) == 0
    assert "Recommended graft W14/H13" in capsys.readouterr().out
    assert json.loads((out / "summary.json").read_text()) == summary
    assert (out / "plan.md").read_text() == written["plan.md"].decode()
    for name in written:
        assert (out / name).stat().st_size > 100, name
    assert (out / "study" / "sizing_map.png").is_file()
    assert main(["report", str(out), "--target-coaptation", "2"]) == 2
    other = _patient(root_diameter_mm=23.0)
    with pytest.raises(OutputConflictError, match="other inputs"):
        run_plan(other, out, MPI.COMM_SELF, mesh_size_mm=2.0, case_function=stand_in_case)


def test_report_on_a_plan_whose_study_does_not_match_its_patient(tmp_path, caplog, quiet_cli):
    from valve_dolfinx.cli import main
    from valve_dolfinx.plan.runner import run_plan

    out = tmp_path / "plan"
    run_plan(_patient(), out, MPI.COMM_SELF, mesh_size_mm=2.0, case_function=stand_in_case)
    write_patient(out / "patient.toml", _patient(paths=1))
    assert main(["report", str(out)]) == 4
    assert "run with other settings than" in caplog.text and "valve-dolfinx plan" in caplog.text


def test_a_plan_names_the_closest_graft_when_none_qualifies(tmp_path):
    """A given target of 2.5 mm: the surface's highest size is the largest, W14/H27, and at
    23 mm it is 0.66 mm short (:func:`surface_margin`), nine times the paths' scatter: no
    graft, W14/H27 the closest."""
    from valve_dolfinx.plan.runner import run_plan

    outcome = run_plan(_patient(target_coaptation_mm=2.5), tmp_path, MPI.COMM_SELF,
                       mesh_size_mm=2.0, case_function=stand_in_case)
    rec = outcome.answers.values[0]
    study, answer = rec.recommendation, rec.recommendation.answer
    assert rec.graft is None and rec.closest == GraftSize(14.0, 27.0)
    assert study.target_mm == 2.5 and set(study.targets_mm.values()) == {2.5}
    shortfall = -surface_margin((14.0, 27.0), 23.0, 2.5)
    assert shortfall == pytest.approx(0.66) and shortfall > 3 * PATH_SCATTER_MM
    assert answer.shortfall_mm == pytest.approx(shortfall, abs=0.02)
    assert rec.name(answer.limiting_member) == "root 23.0 mm"
    assert (tmp_path / "template_W14_H27.pdf").is_file()
    headline = rec.headline()
    assert "No graft in the studied range is robust" in headline
    assert f"0.66 mm short in its worst member, in root 23.0 mm (the model's resolution: " \
        f"{PATH_SCATTER_MM:.2f} mm)" in headline


def test_diameters_beyond_the_leaflets_reach_are_not_computed(tmp_path):
    """A 25.5 ± 1 mm root with a 22 mm free edge: 26.5 mm is beyond the closed-form reach,
    24.5 and 25.5 mm are not.  Only those two are computed; no graft is robust over the
    uncertainty.  In the members computed the surface's highest size, W14/H27, is 0.085 mm
    short at 25.5 mm (:func:`surface_margin`), more than the paths' scatter of 0.071 mm:
    it is named the closest, with its shortfall."""
    from valve_dolfinx.plan.runner import run_plan

    assert not free_edge_reach(22.0, 26.5, 80.0).can_seal
    assert free_edge_reach(22.0, 25.5, 80.0).can_seal
    patient = _patient(root_diameter_mm=25.5)
    outcome = run_plan(patient, tmp_path, MPI.COMM_SELF, mesh_size_mm=2.0,
                       case_function=stand_in_case)
    rec = outcome.answers.values[0]
    study, answer = rec.recommendation, rec.recommendation.answer
    assert rec.unsealable_roots_mm == (26.5,)
    assert rec.unsealable_reason == free_edge_reach(22.0, 26.5, 80.0).sentence()
    assert [rec.name(m) for m in study.members] == [_words(d, p) for d in (24.5, 25.5)
                                                     for p in (1, 2)]
    names = _case_names(tmp_path)
    assert len(names) == 2 + 4 * 2 * 2 and not any("26.5" in n for n in names)
    shortfall = -surface_margin((14.0, 27.0), 25.5)
    assert shortfall == pytest.approx(0.085) and shortfall > PATH_SCATTER_MM
    assert rec.graft is None and rec.closest == GraftSize(14.0, 27.0)
    assert answer.shortfall_mm == pytest.approx(shortfall, abs=0.01)
    assert answer.size is None and answer.margin_mm is None
    assert rec.name(answer.limiting_member) == "root 25.5 mm"
    headline = rec.headline()
    assert headline.startswith("No graft is robust over the root's uncertainty")
    assert "cannot seal a 26.5 mm root whatever the graft" in headline
    assert "The closest is W14/H27, 0.09 mm short in its worst member" in headline
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["answers"]["values"][0]["unsealable_roots_mm"] == [26.5]
    assert summary["answers"]["values"][0]["closest"]["label"] == "W14/H27"
    text = _pdf_text(tmp_path / "plan.pdf")
    assert "Not computed: the 26.5 mm root" in text
    assert "The root's upper bound, 26.5 mm, is beyond that" in text


def test_a_root_the_leaflets_cannot_span_is_answered_without_computing(tmp_path, capsys,
                                                                      quiet_cli):
    from valve_dolfinx.cli import main
    from valve_dolfinx.plan.runner import run_plan

    patient = _patient(root_diameter_mm=30.0, leaflet_free_edge_mm=20.0)
    outcome = run_plan(patient, tmp_path, MPI.COMM_SELF, mesh_size_mm=2.0,
                       case_function=no_case)
    assert outcome.answers.values[0].cannot_seal == outcome.reach.sentence()
    assert not outcome.reach.can_seal and outcome.templates == []
    assert not (tmp_path / "study").exists()
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["answers"]["values"][0]["cannot_seal"].startswith("The native leaflets cannot")
    assert "cannot seal this 30.0 mm root" in _pdf_text(tmp_path / "plan.pdf")
    (tmp_path / "summary.json").unlink()
    assert main(["report", str(tmp_path)]) == 0
    assert json.loads((tmp_path / "summary.json").read_text()) == summary


@pytest.mark.mpi
def test_a_plan_under_mpi_gives_the_serial_summary(tmp_path_factory, parallel_world):
    """Under mpirun -n 2 the stand-in plan writes the summary of a serial plan."""
    from valve_dolfinx.plan.runner import run_plan

    comm = parallel_world
    root = Path(comm.bcast(str(tmp_path_factory.mktemp("plan")) if comm.rank == 0 else None))
    patient = _patient()
    world = run_plan(patient, root / "world", comm, mesh_size_mm=2.0,
                     case_function=stand_in_case)
    assert world.answers.values[0].graft == GraftSize(14.0, 13.0)  # on every rank
    if comm.rank == 0:
        run_plan(patient, root / "serial", MPI.COMM_SELF, mesh_size_mm=2.0,
                 case_function=stand_in_case)
        summaries = [json.loads((root / f / "summary.json").read_text())
                     for f in ("world", "serial")]
        assert summaries[0] == summaries[1]
        assert summaries[0]["run"]["cases"] == 27


# --- a plan with comparison axes --------------------------------------------------------------
#: the stand-in's loss of coaptation of a graft at 2000 kPa against 200 kPa (mm)
STIFF_LOSS_MM = 0.088


def stiff_case(config, out_dir: Path, comm, *, start: Path | None = None) -> dict:
    """:func:`stand_in_case` with the graft's flexural modulus: a graft's height falls
    linearly by :data:`STIFF_LOSS_MM` from 200 to 2000 kPa (the normal valve has no graft:
    the same at both)."""
    result = stand_in_case(config, out_dir, comm, start=start)
    if config.geometry.has_graft:
        result["min_coaptation_height_mm"] -= STIFF_LOSS_MM * (
            config.graft_bending_modulus_kpa - 200.0) / 1800.0
    return result


def test_a_plan_answers_at_each_value_of_a_comparison_axis(tmp_path):
    """--vary graft.bending_modulus_kpa=200,2000 on the stand-in (21, 22, 23 mm, two paths).
    At 200 kPa the answer is W14/H13, as without the axis
    (:func:`test_a_plan_recommends_over_three_diameters_and_the_paths`).  At 2000 kPa every
    graft is 0.088 mm lower: at the widest graft, W14, the surface's margin at 23 mm is
    -0.03 - 0.088 + 0.005 (H - 13) (:func:`surface_margin`), which comes within the paths'
    scatter of 0.0707 mm from H = 13 + 0.0473 / 0.005 = 22.5 %: W14/H23 (a narrower graft
    loses 0.1 mm per per cent of width, which no height in the grid makes up).  The size
    that qualifies at both values is the 2000 kPa answer: the size depends on the
    stiffness.  The normal valve is solved once per diameter, for both values."""
    from valve_dolfinx.plan.runner import run_plan

    patient = _patient(vary={"graft.bending_modulus_kpa": [200, 2000]})
    assert patient.vary == {"graft.bending_modulus_kpa": (200.0, 2000.0)}
    out = tmp_path / "plan"
    outcome = run_plan(patient, out, MPI.COMM_SELF, mesh_size_mm=2.0,
                       case_function=stiff_case)
    answers = outcome.answers
    assert answers.varied and answers.axes == {"graft.bending_modulus_kpa": [200.0, 2000.0]}
    soft, stiff = answers.values
    assert soft.comparison == {"graft.bending_modulus_kpa": 200.0}
    assert stiff.comparison == {"graft.bending_modulus_kpa": 2000.0}
    threshold = 13 + (0.03 + STIFF_LOSS_MM - PATH_SCATTER_MM) / 0.005
    assert threshold == pytest.approx(22.46, abs=0.01)
    assert soft.graft == GraftSize(14.0, 13.0)
    assert soft.recommendation.answer.margin_mm == pytest.approx(
        surface_margin((14.0, 13.0), 23.0), abs=0.02)
    graft = stiff.graft
    assert graft.width_pct == 14.0 and abs(graft.height_pct - math.ceil(threshold)) <= 1
    assert stiff.recommendation.answer.margin_mm == pytest.approx(
        surface_margin((14.0, graft.height_pct), 23.0) - STIFF_LOSS_MM, abs=0.02)
    # the size depends on the stiffness: what qualifies at both is the stiff answer
    assert answers.common == graft
    assert answers.kind == "graft"
    dependence = answers.dependence()
    assert dependence.startswith("The answer differs with graft.bending_modulus_kpa: "
                                 f"W14/H13 at 200, {graft.label} at 2000.")
    assert (f"{graft.label} (+14 % width, +{graft.height_pct:g} % height) is the smallest size "
            "that qualifies at every value (solved at 2000, read from the surface at 200)") in (
        dependence)
    assert answers.headline() == dependence
    # one study: the normal valve once per diameter, every graft at both values
    names = _case_names(out)
    normals = [n for n in names if n.startswith("normal")]
    assert normals == [f"normal__root.loaded_diameter_mm={d}" for d in (21, 22, 23)]
    grid = [n for n in names if not n.startswith("normal")
            and n.split("__")[0] in ("W7_H13", "W7_H27", "W14_H13", "W14_H27")]
    assert len(grid) == 2 * 4 * 3 * 2
    # the files: a sizing map per value, the templates of both answers, the page
    for value in (200, 2000):
        assert (out / f"sizing_map__graft.bending_modulus_kpa={value}.png").stat().st_size \
            > 10_000
    assert not (out / "sizing_map.png").exists()
    assert {t.graft for t in outcome.templates} == {GraftSize(14.0, 13.0), graft}
    summary = json.loads((out / "summary.json").read_text())["answers"]
    assert summary["axes"] == {"graft.bending_modulus_kpa": [200.0, 2000.0]}
    assert summary["common"]["label"] == graft.label
    assert [v["comparison"] for v in summary["values"]] == [
        {"graft.bending_modulus_kpa": 200.0}, {"graft.bending_modulus_kpa": 2000.0}]
    assert [v["graft"]["label"] for v in summary["values"]] == ["W14/H13", graft.label]
    markdown = (out / "plan.md").read_text()
    for words in (f"**{dependence}**", "### At graft.bending_modulus_kpa=2000",
                  f"**Recommended graft {graft.label}",
                  "sizing_map__graft.bending_modulus_kpa=2000.png",
                  "## Every graft over the members at graft.bending_modulus_kpa=200",
                  "| compared (--vary) | graft.bending_modulus_kpa: 200, 2000 |"):
        assert words in markdown, words
    text = _pdf_text(out / "plan.pdf")
    for words in ("Sizing map at graft.bending_modulus_kpa=200",
                  "Sizing map at graft.bending_modulus_kpa=2000",
                  f"At graft.bending_modulus_kpa=2000: {graft.label} (+14 % width",
                  "The closed valve of each value's graft: plan.md"):
        assert words in text, words
    # patient.toml keeps the axis: rerunning it recomputes nothing
    assert read_patient(out / "patient.toml") == replace(patient, mesh_size_mm=2.0)
    run_plan(read_patient(out / "patient.toml"), out, MPI.COMM_SELF, case_function=no_case)


# --- the command line --------------------------------------------------------------------
@pytest.mark.parametrize("args,expected", [
    (["--root-diameter", "55"], "root_diameter_mm (--root-diameter) = 55.0"),
    (["--root-diameter", "22", "--root-uncertainty", "4"], "root_uncertainty_mm"),
    (["--root-diameter", "22", "--leaflet-free-edge", "22"], "needs leaflet_height_mm"),
    (["--root-diameter", "22", "--leaflet-free-edge", "70", "--leaflet-height", "13"],
     "leaflet_free_edge_mm (--leaflet-free-edge) = 70.0"),
    (["--root-diameter", "22", "--pressure", "300"], "pressure_mmhg"),
    (["--root-diameter", "22", "--widths", "-5"], "graft_widths_pct"),
    (["--root-diameter", "22", "--template", "14"], "--template '14'"),
    (["--root-diameter", "22", "--mesh-size", "3.0"], "mesh_size"),
    (["--root-diameter", "22", "--paths", "4"], "paths (--paths)"),
    (["--root-diameter", "22", "--paths", "0"], "paths (--paths)"),
    ([], "root_diameter_mm is missing"),
    # comparison axes: checked as a sweep's, none the plan sets itself, at most 3 values
    (["--root-diameter", "22", "--vary", "graft.bending_modulus_kpa=200,-5"],
     "vary (--vary) graft.bending_modulus_kpa=-5"),
    (["--root-diameter", "22", "--vary", "graft.bending_modulus_kpa"], "give KEY=V1,V2"),
    (["--root-diameter", "22", "--vary", "root.loaded_diameter_mm=21,23"],
     "the plan sets it from --root-diameter and --root-uncertainty"),
    (["--root-diameter", "22", "--vary", "loading.pressure_mmhg=80,100"], "from --pressure"),
    (["--root-diameter", "22", "--vary", "graft.bending_modulus_kpa=200,2000",
      "--vary", "graft.material.thickness_mm=0.4,0.5"], "2 × 2 = 4 combinations"),
    (["--root-diameter", "22", "--vary", "graft.bending_modulus_kpa=200",
      "--vary", "graft.bending_modulus_kpa=2000"], "given twice"),
    (["--root-diameter", "22", "--vary", "graft.placement=billowed"],
     "numerical path 2"),
])
def test_cli_plan_stops_on_bad_input_before_any_computation(tmp_path, caplog, args, expected):
    from valve_dolfinx.cli import main

    out = tmp_path / "plan"
    assert main(["plan", "--out", str(out), *args]) == 2
    assert expected in caplog.text
    assert not out.exists()


def test_cli_plan_reads_a_patient_file_and_names_it_in_errors(tmp_path):
    bad = tmp_path / "PATIENT.toml"
    bad.write_text('root_diameter_mm = 22.0\nleaflet_free_edge = 22.0\n')
    out = tmp_path / "plan"
    proc = subprocess.run([sys.executable, "-m", "valve_dolfinx.cli", "plan", str(bad),
                           "--out", str(out)], capture_output=True, text=True, timeout=300,
                          cwd=ROOT)
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    assert f"{bad}: unknown key 'leaflet_free_edge'" in proc.stderr
    assert "leaflet_free_edge_mm (mm)" in proc.stderr
    assert not out.exists()


def test_patient_toml_documents_every_key():
    text = patient_toml(PatientInput(root_diameter_mm=22.0))
    assert "# target_coaptation_mm = (unset)" in text
    for key, spec in FIELDS.items():
        assert f"{key} = " in text and spec.meaning[:20] in text


def test_an_answer_not_solved_itself_is_said_to_be_a_prediction():
    """An answer whose size is unsolved in some member (the rounds of confirmation spent)
    claims nothing a solve did not show: its headline says it is read from the surface and
    which sizes were solved to confirm it; one solved in every member keeps the plain claim."""
    rec = answer((14, 23), -0.04, limiting="root 20.0 mm", members=("root 20.0 mm", "b"))
    assert "It converges, seals and reaches" in rec.headline()
    rec.recommendation.confirm = ["root 20.0 mm", "b"]
    rec.recommendation.confirmations = [{"graft": "W14/H26", "margin_mm": -0.10,
                                "limiting_member": "b", "holds": True}]
    words = rec.headline()
    assert "read from the surface fitted to the solved grafts" in words
    assert "predicted margin is -0.04 mm" in words
    assert "It was not solved itself" in words and "(W14/H26)" in words
    assert "It converges, seals and reaches" not in words
