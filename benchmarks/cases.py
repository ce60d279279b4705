"""Case names of the benchmarks' command lines (``normal``, ``W21/H27``)."""

from __future__ import annotations

import argparse
import re


def parse_case(text: str) -> tuple[float, float] | None:
    """``normal`` -> None; ``W21/H27`` (or ``W21_H27``, ``21/27``) -> (21.0, 27.0)."""
    if text.strip().lower() == "normal":
        return None
    match = re.fullmatch(r"\s*W?([\d.]+)\s*[/_,x]\s*H?([\d.]+)\s*", text, re.IGNORECASE)
    if match is None:
        raise argparse.ArgumentTypeError(f"case {text!r}: expected 'normal' or 'W<w>/H<h>'")
    return float(match[1]), float(match[2])
