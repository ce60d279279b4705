"""A case's settings as dataclass fields that carry their own unit and meaning.

Every parameter set of a case configuration (:class:`~valve_dolfinx.config.CaseConfig` and
its sections: the geometry, the materials, the root, the contact, the solver paths)
declares each setting with :func:`setting`, which puts the unit and the meaning in the
field's ``metadata``.  That is the one place they are written: `valve-dolfinx config`'s
comments, the range checks' messages (:func:`check_setting`) and the settings table of
docs/outputs.md (:func:`valve_dolfinx.config.settings_table_markdown`) all read them there.

Field metadata, not a typed-settings library such as pydantic: the parameter sets already
are (mostly frozen) dataclasses validated in ``__post_init__``, which code and tests build
directly; metadata adds nothing to install, changes no constructor, value or hash, and keeps
the configuration importable without DOLFINx.

A leaf module: the parameter sets import it, and it imports none of them.
"""

from __future__ import annotations

from dataclasses import MISSING, Field, field
from typing import Any

from valve_dolfinx.exceptions import check_range

__all__ = ["NOT_A_SETTING", "setting", "is_setting", "setting_field", "check_setting"]

#: ``metadata`` of a parameter set's field that is not a setting: a fixed number of the
#: model, or a label, that every case takes at its default.  It is left out of the
#: configuration, its TOML and its hash; code and tests that build the parameter set
#: themselves may still give it (``ContactParameters.taper``, ``FungMaterial.name``).
NOT_A_SETTING = {"setting": False}


def setting(default: Any = MISSING, unit: str = "", meaning: str = "", *,
            default_factory: Any = MISSING) -> Any:
    """A dataclass field that is a setting: ``x: float = setting(1.0, "mm", "what x is")``.

    ``unit`` is "" for a dimensionless setting or a switch; ``meaning`` is the short
    description written beside the setting wherever it is shown.  Leave ``default`` (and
    ``default_factory``) out for a field without a default.  Where the configuration file
    shows the setting, and under which key (the field's name with the suffix of its unit),
    is :data:`valve_dolfinx.config.LAYOUT`'s business.
    """
    if not meaning:
        raise TypeError("setting(): give the setting's meaning")
    metadata: dict[str, Any] = {"unit": unit, "meaning": meaning}
    return field(default=default, default_factory=default_factory, metadata=metadata)


def is_setting(f: Field) -> bool:
    """Whether the field is a setting (every field but those marked :data:`NOT_A_SETTING`)."""
    return f.metadata.get("setting", True)


def setting_field(section: Any, name: str) -> Field:
    """The field ``name`` of a parameter set (class or instance) that is a setting with its
    unit and meaning; KeyError naming the class if it has no such field or the field was
    not declared with :func:`setting`."""
    cls = section if isinstance(section, type) else type(section)
    f = getattr(cls, "__dataclass_fields__", {}).get(name)
    if f is None or not is_setting(f):
        raise KeyError(f"{cls.__name__} has no setting {name!r}")
    if "meaning" not in f.metadata:
        raise KeyError(f"{cls.__name__}.{name} is a setting without its unit and meaning: "
                       "declare it with valve_dolfinx.setting_fields.setting(default, unit, "
                       "meaning)")
    return f


def check_setting(section: Any, name: str, low: float | None = None,
                  high: float | None = None, *, label: str = "", **kwargs: Any) -> float:
    """:func:`~valve_dolfinx.exceptions.check_range` of the setting ``name`` of the parameter
    set ``section`` (an instance), with the unit of its field; ``label`` names it in the
    message (default ``name``); the other keywords are check_range's."""
    unit = setting_field(section, name).metadata["unit"]
    return check_range(label or name, getattr(section, name), low, high, unit=unit, **kwargs)
