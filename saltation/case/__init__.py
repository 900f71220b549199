"""The case: the TOML schema as frozen dataclasses, units resolved once, TOML input and
output (``schema.py``)."""
from .schema import Case, CaseError, dump_toml, load_case, resolve_domain

__all__ = ["Case", "CaseError", "load_case", "dump_toml", "resolve_domain"]
