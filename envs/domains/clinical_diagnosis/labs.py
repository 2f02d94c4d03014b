"""Laboratory reference intervals and result interpretation.

The catalogue is authored (`authored/reference_ranges.json`: adult intervals and critical limits in
conventional units); the build joins each analyte to labunits' LOINC record to add its SI unit and
conversion factor when labunits lists the same analyte in the same conventional unit.

Flags, for a numeric result x with interval [low, high] and critical limits cl / ch:
    x <= cl -> "critical low";  x < low -> "low";  x >= ch -> "critical high";  x > high -> "high";
    otherwise "normal". Qualitative results are "normal" when they equal the analyte's normal text
    (case-insensitive), else "abnormal".
"""

from __future__ import annotations

import re
from dataclasses import dataclass

FLAGS = ("critical low", "low", "normal", "high", "critical high")


def _norm(text: str) -> str:
    text = text.replace("\u03bc", "u").replace("\u00b5", "u")
    return re.sub(r"[^a-z0-9]+", " ", text.lower()).strip()


def _unit_norm(unit: str) -> str:
    return unit.replace("\u03bc", "u").replace("\u00b5", "u").replace(" ", "").lower()


@dataclass(frozen=True)
class Interval:
    low: float | None
    high: float | None
    critical_low: float | None
    critical_high: float | None


class LabCatalog:
    """Analyte lookup by key, name, alias or LOINC, and interpretation against the interval."""

    def __init__(self, analytes: list[dict]) -> None:
        self.analytes = {a["key"]: a for a in analytes}
        self._names: dict[str, str] = {}
        for a in analytes:
            for label in [a["key"], a["name"], *a.get("aliases", []), a.get("loinc") or ""]:
                if label:
                    self._names.setdefault(_norm(label), a["key"])

    def resolve(self, name: str) -> str | None:
        key = self._names.get(_norm(name))
        if key is None:
            key = self._names.get(_norm(name).replace(" ", "_"))
        return key

    def known(self) -> list[str]:
        return sorted(self.analytes)

    def interval(self, key: str, sex: str | None) -> Interval:
        a = self.analytes[key]
        if "low" in a or "high" in a:
            low, high = a.get("low"), a.get("high")
        else:
            band = a.get(sex or "") or None
            if band is None:  # sex unknown: the union of both intervals
                low = min(a["male"]["low"], a["female"]["low"])
                high = max(a["male"]["high"], a["female"]["high"])
            else:
                low, high = band["low"], band["high"]
        return Interval(low, high, a.get("critical_low"), a.get("critical_high"))

    def to_conventional(self, key: str, value: float, unit: str | None) -> tuple[float, str | None]:
        """Convert a value given in the analyte's SI unit to its conventional unit (value, note)."""
        a = self.analytes[key]
        if unit is None or _unit_norm(unit) == _unit_norm(a["unit"]):
            return value, None
        si_unit, factor = a.get("si_unit"), a.get("si_factor")
        if si_unit and factor and _unit_norm(unit) == _unit_norm(si_unit):
            converted = value / factor
            return converted, f"{value:g} {si_unit} = {converted:.4g} {a['unit']} (factor {factor:g}, labunits)"
        accepted = [a["unit"]] + ([si_unit] if si_unit and factor else [])
        raise ValueError(f"unit {unit!r} is not accepted for {a['name']}; use one of {accepted}")

    def flag(self, key: str, value: float | str, sex: str | None) -> str:
        a = self.analytes[key]
        if a.get("qualitative"):
            return "normal" if _norm(str(value)) == _norm(a["normal_text"]) else "abnormal"
        x = float(value)
        iv = self.interval(key, sex)
        if iv.critical_low is not None and x <= iv.critical_low:
            return "critical low"
        if iv.critical_high is not None and x >= iv.critical_high:
            return "critical high"
        if iv.low is not None and x < iv.low:
            return "low"
        if iv.high is not None and x > iv.high:
            return "high"
        return "normal"

    def describe(self, key: str, sex: str | None) -> dict:
        a = self.analytes[key]
        if a.get("qualitative"):
            return {"test": key, "name": a["name"], "loinc": a.get("loinc"), "unit": "qualitative",
                    "normal": a["normal_text"]}
        iv = self.interval(key, sex)
        out = {"test": key, "name": a["name"], "loinc": a.get("loinc"), "unit": a["unit"],
               "reference_range": f"{_fmt(iv.low)}-{_fmt(iv.high)} {a['unit']}",
               "critical_low": iv.critical_low, "critical_high": iv.critical_high}
        if "male" in a:
            out["sex_specific"] = {s: f"{a[s]['low']:g}-{a[s]['high']:g}" for s in ("male", "female")}
        if a.get("si_unit"):
            out["si_unit"], out["si_factor"] = a["si_unit"], a["si_factor"]
        if a.get("note"):
            out["note"] = a["note"]
        return out


def _fmt(x: float | None) -> str:
    return "" if x is None else f"{x:g}"


def join_labunits(analytes: list[dict], labunits: dict[str, dict]) -> tuple[list[dict], int]:
    """Add si_unit / si_factor from labunits (keyed by LOINC) where the conventional units agree."""
    out, joined = [], 0
    for a in analytes:
        a = dict(a)
        rec = labunits.get(a.get("loinc") or "")
        if rec and not a.get("qualitative") and _unit_norm(rec["traditional_units"]).replace("meq", "mmol") == \
                _unit_norm(a["unit"]) and _unit_norm(rec["si_units"]) != _unit_norm(a["unit"]):
            a["si_unit"] = rec["si_units"].replace("\u03bc", "u").replace("\u00b5", "u")
            a["si_factor"] = rec["conversion_factor"]
            a["si_source"] = "labunits 0.2.1"
            joined += 1
        out.append(a)
    return out, joined
