"""A script of benchmarks/ loaded as a module, for the tests that drive it (the folder is
not a package)."""
import importlib.util
from pathlib import Path

BENCHMARKS = Path(__file__).resolve().parents[2] / "benchmarks"


def load(stem: str):
    """benchmarks/<stem>.py, executed as the module ``stem``."""
    spec = importlib.util.spec_from_file_location(stem, BENCHMARKS / f"{stem}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod
