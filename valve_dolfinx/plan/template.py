"""The graft template's files: the graft at true size on an A4 page, to print and cut from
(SPEC §9).

:func:`write_template` writes the page of :func:`valve_dolfinx.plotting.template.
template_drawing` as SVG in millimetre units and as PDF at true size, and a PNG of the
graft and its dimensions for the report; the graft's outline and cut line are
:class:`~valve_dolfinx.geometry.template.GraftTemplate`'s.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

from valve_dolfinx.geometry.outline import GraftSize
from valve_dolfinx.geometry.template import GraftTemplate
from valve_dolfinx.io import atomic_write
from valve_dolfinx.plotting.page import drawing_svg, page_figure, region_inches
from valve_dolfinx.plotting.template import template_drawing

__all__ = ["TemplateFiles", "write_template"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class TemplateFiles:
    """The files of one template and the dimensions they draw (mm)."""

    svg: Path
    pdf: Path
    png: Path
    graft: GraftSize
    free_edge_mm: float
    height_mm: float
    cut_width_mm: float
    cut_height_mm: float

    def to_dict(self) -> dict:
        return {"graft": self.graft.label, "svg": self.svg.name, "pdf": self.pdf.name,
                "png": self.png.name, "free_edge_mm": self.free_edge_mm,
                "height_mm": self.height_mm, "cut_width_mm": self.cut_width_mm,
                "cut_height_mm": self.cut_height_mm}


def write_template(template: GraftTemplate, out: str | Path, patient_line: str = ""
                   ) -> TemplateFiles:
    """Write ``template_W<w>_H<h>.svg``, ``.pdf`` (A4, true size) and ``.png`` (the graft
    and its dimensions, for the report) into ``out``, each atomically."""
    out = Path(out)
    stem = out / f"template_{template.graft.stem}"
    page = template_drawing(template, patient_line)
    title = f"graft template {template.graft.label}, {template.label}"
    svg = atomic_write(stem.with_suffix(".svg"),
                       lambda tmp: tmp.write_text(drawing_svg(page, title), encoding="utf-8"))
    fig = page_figure(page)
    pdf = atomic_write(stem.with_suffix(".pdf"), lambda tmp: fig.savefig(
        tmp, format="pdf", metadata={"Title": title}))
    box = region_inches(page, "thumbnail")
    png = atomic_write(stem.with_suffix(".png"),
                       lambda tmp: fig.savefig(tmp, format="png", dpi=200, bbox_inches=box))
    s = template.shape
    log.info("graft template %s: %.1f x %.1f mm cut piece -> %s.{svg,pdf,png}",
             template.graft.label, template.cut_width_mm, template.cut_height_mm, stem)
    return TemplateFiles(svg, pdf, png, template.graft, s.free_edge_length, s.height,
                         template.cut_width_mm, template.cut_height_mm)
