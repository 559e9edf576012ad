"""Cura's own settings from the ``;SETTING_3`` footer of a G-code file saved by Cura.

Cura's G-code writer appends the print's changed settings as JSON, in lines of
``;SETTING_3 <text>``: ``{"global_quality": "<ini>", "extruder_quality":
["<ini>", ...]}``, each ini a serialized settings container whose
``[values]`` section holds the settings the user or the quality profile
changed (per-object settings are not in it), cut into lines of 80 characters.  Files sliced by the CuraEngine
command line have no footer.
"""

from __future__ import annotations

import configparser
import json
import re
from dataclasses import dataclass, field

__all__ = ["CuraFooter", "read_footer"]

_PREFIX = ";SETTING_3 "
# Cura escapes the JSON text for comments: a backslash doubled, newline and carriage return as \n and \r
_ESCAPED = re.compile(r"\\(\\|n|r)")
_UNESCAPE = {"\\": "\\", "n": "\n", "r": "\r"}


@dataclass
class CuraFooter:
    """The settings of a Cura-saved G-code: global values and one dict per extruder (strings, as Cura wrote them)."""

    global_values: dict[str, str] = field(default_factory=dict)
    extruder_values: list[dict[str, str]] = field(default_factory=list)

    @property
    def found(self) -> bool:
        return bool(self.global_values or self.extruder_values)

    def value(self, key: str, extruder: int = 0) -> str | None:
        """A setting as Cura resolved it for an extruder's stack: the extruder's own value, else the global one."""
        if 0 <= extruder < len(self.extruder_values) and key in self.extruder_values[extruder]:
            return self.extruder_values[extruder][key]
        return self.global_values.get(key)

    def number(self, key: str, extruder: int = 0) -> float | None:
        """A numeric setting, None when absent or a formula (``=...``)."""
        text = self.value(key, extruder)
        if text is None:
            return None
        try:
            return float(text)
        except ValueError:
            return None

    def infill_density(self, extruder: int = 0) -> float | None:
        """The density Cura's infill prints at, a fraction: ``infill_sparse_density`` times the infill
        line multiplier (each line printed that many times side by side), at most 1."""
        percent = self.number("infill_sparse_density", extruder)
        if percent is None or percent < 0:
            return None
        multiplier = self.number("infill_multiplier", extruder) or 1.0
        return min(1.0, percent / 100.0 * max(1.0, multiplier))

    def infill_pattern(self, extruder: int = 0) -> str | None:
        return self.value("infill_pattern", extruder)


def _ini_values(text: str) -> dict[str, str]:
    parser = configparser.ConfigParser(interpolation=None, strict=False)
    try:
        parser.read_string(text)
    except configparser.Error:
        return {}
    if not parser.has_section("values"):
        return {}
    return {key: value.strip() for key, value in parser.items("values")}


def read_footer(text: str) -> CuraFooter:
    """The ``;SETTING_3`` footer of G-code `text` (usually its last chunk); empty when there is none or it is damaged."""
    at = text.find(_PREFIX)
    if at < 0:
        return CuraFooter()
    parts = [line[len(_PREFIX):] for line in text[at:].splitlines() if line.startswith(_PREFIX)]
    try:
        data = json.loads(_ESCAPED.sub(lambda m: _UNESCAPE[m.group(1)], "".join(parts)))
    except ValueError:
        return CuraFooter()
    if not isinstance(data, dict):
        return CuraFooter()
    global_values = _ini_values(data["global_quality"]) if isinstance(data.get("global_quality"), str) else {}
    extruders = data.get("extruder_quality") or []
    extruder_values = [_ini_values(e) if isinstance(e, str) else {} for e in extruders] if isinstance(extruders, list) else []
    return CuraFooter(global_values, extruder_values)
