"""flowfields._openmp: idle OpenMP threads spin briefly (GOMP_SPINCOUNT) unless the user
chose otherwise, and the setting is made before libgomp is loaded (else it is never read)."""
import os
import subprocess
import sys

PROBE = """
import os
import saltation
loaded = any("libgomp" in line for line in open("/proc/self/maps"))
print(os.environ.get("GOMP_SPINCOUNT"), loaded)
"""


def _probe(**env):
    base = {k: v for k, v in os.environ.items() if k not in ("GOMP_SPINCOUNT", "OMP_WAIT_POLICY")}
    out = subprocess.run([sys.executable, "-c", PROBE], env={**base, **env}, capture_output=True, text=True,
                         check=True)
    spin, loaded = out.stdout.split()
    return spin, loaded == "True"


def test_import_sets_a_short_spin_before_libgomp_is_loaded():
    from flowfields._openmp import SPIN_COUNT

    spin, loaded = _probe()
    assert spin == str(SPIN_COUNT)
    # libgomp reads GOMP_SPINCOUNT once, when it is loaded: that must come later (the first
    # parallel kernel call), or the setting does nothing
    assert not loaded


def test_a_users_own_setting_is_kept():
    assert _probe(GOMP_SPINCOUNT="300000")[0] == "300000"
    assert _probe(OMP_WAIT_POLICY="active")[0] == "None"
