"""Planning one patient's repair (SPEC §9): measured inputs, a robust recommendation, the graft
drawn at true size and a one-page report.

* :mod:`~valve_dolfinx.plan.patient`: the measured inputs, range-checked, from and to TOML;
* :mod:`~valve_dolfinx.plan.reach`: whether the native free edges can span the root at all;
* :mod:`~valve_dolfinx.plan.recommendation`: the plan's answer;
* :mod:`~valve_dolfinx.plan.template`: writes the graft template (SVG and PDF, A4, true size);
* :mod:`~valve_dolfinx.plan.report`: what ``plan.md`` and the one-page ``plan.pdf`` say, written;
* :mod:`~valve_dolfinx.plan.runner`: ``run_plan``, which runs the plan's study (DOLFINx).
"""
