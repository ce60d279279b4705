"""An output folder checked before any computation; writing files atomically; JSON results;
the valve surface as VTK for ParaView.

The valve mesh's own reloadable format is :func:`valve_dolfinx.geometry.valve.save_valve_mesh`.
"""

from __future__ import annotations

import json
import logging
import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from valve_dolfinx.exceptions import OutputNotFolderError, OutputNotWritableError

__all__ = [
    "check_output_folder",
    "atomic_write",
    "write_json",
    "read_json",
    "export_valve_vtu",
]

log = logging.getLogger(__name__)


def check_output_folder(path: str | Path, option: str = "--out") -> Path:
    """Create the folder ``path`` if it is missing and prove it writable with a temporary
    file: call it before any computation.  ``option`` is how the user gave it (messages).

    Raises
    ------
    OutputNotFolderError
        If ``path``, or a folder above it, is a file.
    OutputNotWritableError
        If ``path`` cannot be created or written (permissions, a read-only file system).
    """
    path = Path(path)
    try:
        path.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=path, prefix=".probe-"):
            pass
    except (FileExistsError, NotADirectoryError):
        blocker = next(p for p in (path, *path.parents) if p.exists())
        where = "is a file" if blocker == path else f"is below the file {blocker}"
        raise OutputNotFolderError(f"{option} {path} {where}: give a folder for the outputs "
                                   "(it is created if missing)") from None
    except OSError as err:
        raise OutputNotWritableError(
            f"{option} {path} cannot be created or written ({err.strerror or err}); choose "
            "another folder, or fix its permissions") from None
    return path


def atomic_write(path: str | Path, write: Callable[[Path], None]) -> Path:
    """Call ``write(tmp)`` on a temporary file beside ``path``, then rename it into place.

    A crash mid-write never leaves a truncated ``path`` behind; readers see the
    old file or the new one.  The file is flushed to disk before the rename (and
    the folder after it), and gets the mode a plain ``open`` would give it under
    the user's umask (0644 under umask 022), not the temporary file's 0600.

    Raises
    ------
    OutputNotWritableError
        If the folder does not let the file be created, naming the folder.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=path.suffix, dir=path.parent)
    except PermissionError as err:
        raise OutputNotWritableError(
            f"{path.parent} cannot be written ({err.strerror or err}): {path.name} was not "
            "written; fix the folder's permissions, or copy it somewhere writable") from None
    os.close(fd)
    try:
        write(Path(tmp))
        os.chmod(tmp, 0o666 & ~_umask())
        _fsync(tmp, os.O_RDONLY)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    _fsync(path.parent, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    return path


def _umask() -> int:
    """The process's umask: from /proc on Linux, else by setting it and straight back
    (which a thread creating a file at that instant could see)."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _fsync(path: str | Path, flags: int) -> None:
    """Flush ``path`` (a file, or a folder where the platform allows it) to disk."""
    try:
        fd = os.open(path, flags)
    except OSError:  # a folder that cannot be opened (Windows)
        return
    try:
        os.fsync(fd)
    except OSError:  # a file system without fsync on folders
        pass
    finally:
        os.close(fd)


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"cannot write {type(obj).__name__} to JSON")


def write_json(path: str | Path, data: Any) -> Path:
    """Write ``data`` as indented JSON, atomically (NaN written as null)."""
    text = json.dumps(_nan_to_none(data), indent=2, default=_json_default, allow_nan=False)
    return atomic_write(path, lambda tmp: tmp.write_text(text + "\n"))


def _nan_to_none(data: Any) -> Any:
    if isinstance(data, dict):
        return {k: _nan_to_none(v) for k, v in data.items()}
    if isinstance(data, list | tuple):
        return [_nan_to_none(v) for v in data]
    if isinstance(data, float | np.floating) and not np.isfinite(data):
        return None
    return data


def read_json(path: str | Path) -> Any:
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    try:
        return json.loads(path.read_text())
    except json.JSONDecodeError as err:
        raise ValueError(f"{path} is not valid JSON ({err}); delete it to recompute") from err


def export_valve_vtu(valve, path: str | Path, point_data: dict | None = None,
                     cell_data: dict | None = None) -> Path:
    """Write the valve surface with tags and fibres as a VTK ``.vtu`` file through meshio."""
    import meshio

    cd = {"leaflet": valve.cell_tags.astype(np.int32), "fibre": valve.fibres_3d()}
    cd.update(cell_data or {})
    mesh = meshio.Mesh(valve.points, [("triangle", valve.cells)],
                       point_data=point_data or {},
                       cell_data={k: [np.asarray(v)] for k, v in cd.items()})
    path = Path(path).with_suffix(".vtu")
    return atomic_write(path, lambda tmp: meshio.write(tmp, mesh, file_format="vtu"))
