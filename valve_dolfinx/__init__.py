"""valve_dolfinx: aortic valve closure and pericardial leaflet graft sizing with FEniCSx.

The public API::

    import valve_dolfinx as vd

    config = vd.load_config("case.toml", overrides=["loading.pressure_mmhg=100"])
    result = vd.run_case(config, "results/case")        # closes the valve, writes the folder
    case = vd.load_case("results/case")                  # result, configuration, surface
    valve = vd.build_valve(vd.CaseConfig().geometry)     # the unloaded valve mesh
    vd.run_sweep(settings, "results/graft_sweep")        # a sizing study (StudySettings)
    patient = vd.read_patient("PATIENT.toml")            # or vd.PatientInput(root_diameter_mm=22)
    vd.run_plan(patient, "results/plan")                 # one patient's plan, template, report

Importing the package is light: each name is imported on first use, so
``import valve_dolfinx`` loads neither DOLFINx nor the plotting libraries, and
changes no global state of matplotlib or PyVista.
"""

from __future__ import annotations

import importlib
from typing import Any

from valve_dolfinx._version import __version__

__all__ = [
    "__version__",
    "build_valve",
    "CaseConfig",
    "CaseResult",
    "StudySettings",
    "load_config",
    "run_case",
    "run_sweep",
    "load_case",
    "PatientInput",
    "read_patient",
    "run_plan",
]

#: public name -> (module, attribute), imported on first use
_LAZY = {
    "build_valve": ("valve_dolfinx.geometry.valve", "build_valve"),
    "CaseConfig": ("valve_dolfinx.config", "CaseConfig"),
    "load_config": ("valve_dolfinx.config", "load_config"),
    "CaseResult": ("valve_dolfinx.result", "CaseResult"),
    "load_case": ("valve_dolfinx.result", "load_case"),
    "run_case": ("valve_dolfinx.case", "run_case"),
    "StudySettings": ("valve_dolfinx.study.grid", "StudySettings"),
    "run_sweep": ("valve_dolfinx.study.runner", "run_study"),
    "PatientInput": ("valve_dolfinx.plan.patient", "PatientInput"),
    "read_patient": ("valve_dolfinx.plan.patient", "read_patient"),
    "run_plan": ("valve_dolfinx.plan.runner", "run_plan"),
}


def __getattr__(name: str) -> Any:
    try:
        module, attribute = _LAZY[name]
    except KeyError:
        raise AttributeError(f"module 'valve_dolfinx' has no attribute {name!r}") from None
    value = getattr(importlib.import_module(module), attribute)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
