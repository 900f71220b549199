"""Write tests/regression/reference.npz: the fingerprints of every case of cases.py.
Run once before a change that must not change results (python tests/regression/make_reference.py)."""
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from cases import CASES, REFERENCE, run_case  # noqa: E402


def main():
    arrays = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name in CASES:
            fp = run_case(name, Path(tmp) / name)
            print(name, {k: len(v) for k, v in fp.items() if k in ("jumps/particle", "tracks/particle")}, flush=True)
            arrays.update({f"{name}|{k}": v for k, v in fp.items()})
    np.savez_compressed(REFERENCE, **arrays)
    print("wrote", REFERENCE, REFERENCE.stat().st_size, "bytes")


if __name__ == "__main__":
    main()
