"""The numerical paths along which a study solves every cell (SPEC §7).

A loaded valve can have several resting states, and the path from the unloaded
valve decides which one a solve reaches (docs/numerics.md §7, "Resolution").  A
study with ``paths = N`` solves every graft along the first ``N`` paths of
:data:`PATHS`; each path is a case of its own, and the paths are always an
*uncertainty* axis: the recommendation takes the worst of them.

A path is data: the case settings it overrides (dotted keys, as ``--set``
takes them) and where its solve starts.  Every path is cheap and reproducible:
the same path gives the same case on any number of ranks.  The first path is
a warm start from the closed normal valve; the others close the graft valve from
the open, unloaded valve with the slack graft placed in two ways.  The normal valve has no
graft, so it is the
same case on every path (its configuration does not change, see
:meth:`valve_dolfinx.config.CaseConfig.normal_valve`) and is solved once per
member of the other axes.

Nothing here imports DOLFINx.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from valve_dolfinx.exceptions import ParameterError

__all__ = ["StudyPath", "PATHS", "START_FROM_NORMAL", "study_paths"]

#: ``StudyPath.start``: every graft of the path starts from the loaded state of the normal
#: valve of the same member (the runner passes that case's folder to the case function)
START_FROM_NORMAL = "normal"


@dataclass(frozen=True)
class StudyPath:
    """One prescribed numerical path of a study.

    Attributes
    ----------
    number
        1, 2, ...: the path's place in :data:`PATHS` (``--paths N`` takes the first N).
    name
        A short name (reports, member labels).
    description
        What the path does, in a sentence.
    overrides
        Case settings the path sets, ``{"table.key": value}``; no other setting of a
        study (``--set``, ``--vary``, ``--uncertain``) may set them.
    start
        ``None``: every case starts from the unloaded valve; :data:`START_FROM_NORMAL`:
        every graft starts from the loaded normal valve of the same member.
    """

    number: int
    name: str
    description: str
    overrides: Mapping[str, Any] = field(default_factory=dict)
    start: str | None = None

    @property
    def label(self) -> str:
        return f"path {self.number} ({self.name})"


#: The paths, in the order ``--paths N`` takes them
PATHS: tuple[StudyPath, ...] = (
    StudyPath(1, "from the closed valve", "every graft starts from the loaded normal valve "
              "of the same member: the native leaflets where they came to rest, the graft "
              "laid over the closed native leaflet it replaces", start=START_FROM_NORMAL),
    StudyPath(2, "from the open valve", "the slack graft is first bulged 2 mm towards the "
              "valve axis on the unloaded valve and closes with the native leaflets from "
              "there",
              {"graft.placement": "billowed", "graft.billow_mm": 2.0}),
    StudyPath(3, "from the open valve, conformal", "the slack graft is first laid onto the "
              "native leaflet's wrapped surface on the unloaded valve and closes from there "
              "(what `valve-dolfinx run` does)",
              {"graft.placement": "conformal"}),
)


def study_paths(n: Any) -> tuple[StudyPath, ...]:
    """The first ``n`` paths of :data:`PATHS`.

    Raises
    ------
    ParameterError
        If ``n`` is not a whole number from 1 to the number of defined paths.
    """
    defined = "; ".join(f"{p.number}: {p.name}" for p in PATHS)
    if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= len(PATHS):
        raise ParameterError(f"paths = {n!r} must be a whole number from 1 to {len(PATHS)} "
                             f"(the defined numerical paths are {defined})")
    return PATHS[:n]
