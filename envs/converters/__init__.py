"""Converters from public benchmark file formats into gradeable tasks.

Users bring the files (none of these datasets ship in a registry package); each converter reads
the format exactly as the benchmark distributes it and reports malformed rows with file and line.
See `CONVERTERS` for the formats and `hcgym tasks import --format F PATH`.
"""

from envs.converters.base import ConversionResult, RowError
from envs.converters.formats import CONVERTERS, convert

__all__ = ["CONVERTERS", "ConversionResult", "RowError", "convert"]
