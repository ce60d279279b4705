"""The package's version, and the git commit of the source checkout it runs from."""

from __future__ import annotations

import functools
import importlib.metadata
from pathlib import Path

__all__ = ["__version__", "git_commit"]

#: version of this source tree when it is not installed (keep equal to pyproject.toml's)
_SOURCE_VERSION = "0.1.0"

try:
    __version__ = importlib.metadata.version("valve_dolfinx")
except importlib.metadata.PackageNotFoundError:
    __version__ = _SOURCE_VERSION


@functools.cache
def git_commit() -> str | None:
    """The commit checked out in the git work tree holding this package, or None.

    None when the package does not run from a git checkout (an installed copy), or
    the checkout cannot be read.  The files are read directly (no ``git`` process,
    which need not be installed and must not fork under MPI).
    """
    package = Path(__file__).resolve().parent
    try:
        git_dir = _git_dir(package.parent)
        if git_dir is None:
            return None
        head = (git_dir / "HEAD").read_text().strip()
        if not head.startswith("ref:"):
            return head or None  # detached HEAD
        ref = head.split(":", 1)[1].strip()
        common = git_dir
        if (git_dir / "commondir").is_file():  # a linked work tree
            common = (git_dir / (git_dir / "commondir").read_text().strip()).resolve()
        for base in (git_dir, common):
            if (base / ref).is_file():
                return (base / ref).read_text().strip() or None
        packed = common / "packed-refs"
        if packed.is_file():
            for line in packed.read_text().splitlines():
                sha, _, name = line.partition(" ")
                if name.strip() == ref:
                    return sha
    except (OSError, UnicodeDecodeError):
        return None
    return None


def _git_dir(root: Path) -> Path | None:
    """The git directory of the work tree whose top is ``root`` (``.git`` folder or file)."""
    dot_git = root / ".git"
    if dot_git.is_dir():
        return dot_git
    if dot_git.is_file():
        text = dot_git.read_text().strip()
        if text.startswith("gitdir:"):
            return (root / text.split(":", 1)[1].strip()).resolve()
    return None
