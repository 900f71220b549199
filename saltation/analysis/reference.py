"""Published values of Moreno-Casas et al. (2022) for side-by-side tables (SPEC §8).

For comparison only, never for tuning. Concentrations are volume fractions in percent
(C = N (π/6) d³ / (Lx Lz h), SPEC §1), CPU times in seconds for 200 s simulated
(paper Table 3, OpenMP on one server).
"""
from __future__ import annotations

import numpy as np
import pandas as pd

TAU_RATIOS = (1.79, 2.43, 2.67)
CONCENTRATIONS_PCT = (0.04, 0.12, 0.18, 0.26, 0.52, 1.03, 2.07, 3.94)
N_PARTICLES = (1000, 3000, 4500, 6500, 13000, 26000, 52000, 99000)
SIMULATED_S = 200.0
CPU_TIME_S = dict(zip(N_PARTICLES, (3251, 3548, 3761, 4053, 5088, 7662, 14543, 31858)))

# Tables 4-7: rows τ*/τ*c, columns the 8 concentrations above
GAMMA = {
    ("local", "x"): {1.79: (.98, .98, .98, .98, .98, .98, .98, .90),
                     2.43: (.98, .98, .98, .98, .98, .95, .90, .90),
                     2.67: (.98, .98, .98, .98, .98, .98, .95, .90)},
    ("intermediate", "x"): {1.79: (.60, .60, .60, .75, .65, .65, .80, .85),
                            2.43: (.75, .60, .60, .60, .75, .65, .85, .85),
                            2.67: (.73, .73, .60, .73, .63, .65, .80, .85)},
    ("local", "z"): {t: (.98, .98, .98, .98, .98, .98, .90, .90) for t in TAU_RATIOS},
    ("intermediate", "z"): {1.79: (.50, .50, .55, .60, .60, .70, .70, .65),
                            2.43: (.45, .50, .60, .60, .60, .65, .70, .65),
                            2.67: (.55, .55, .55, .55, .60, .60, .65, .70)},
}
TABLE_NUMBER = {("local", "x"): 4, ("intermediate", "x"): 5, ("local", "z"): 6, ("intermediate", "z"): 7}

TAU_TOLERANCE = 0.02  # a run's τ*/τ*c matches a paper row within this
CONCENTRATION_TOLERANCE = 0.25  # and a paper column within this relative difference


def gamma_table() -> pd.DataFrame:
    """The paper's γ as tidy rows: range, direction, tau_ratio, concentration_pct, gamma."""
    rows = []
    for (rng, d), by_tau in GAMMA.items():
        for tau, values in by_tau.items():
            for c, g in zip(CONCENTRATIONS_PCT, values):
                rows.append({"range": rng, "direction": d, "tau_ratio": tau, "concentration_pct": c, "gamma": g,
                             "table": TABLE_NUMBER[(rng, d)]})
    return pd.DataFrame(rows)


def match_case(tau_ratio: float, concentration_pct: float):
    """(paper τ*/τ*c, paper C %) of the paper case this run corresponds to, or a reason
    string when none is close enough."""
    taus = np.asarray(TAU_RATIOS)
    i = int(np.argmin(np.abs(taus - tau_ratio)))
    if abs(taus[i] - tau_ratio) > TAU_TOLERANCE:
        return None, None, f"no paper case at τ*/τ*c = {tau_ratio:.3g} (paper: {', '.join(map(str, TAU_RATIOS))})"
    cs = np.asarray(CONCENTRATIONS_PCT)
    j = int(np.argmin(np.abs(np.log(cs / concentration_pct))))
    if abs(cs[j] / concentration_pct - 1) > CONCENTRATION_TOLERANCE:
        return float(taus[i]), None, (f"no paper case within {100 * CONCENTRATION_TOLERANCE:.0f} % of C = "
                                      f"{concentration_pct:.3g} % (nearest {cs[j]:g} %)")
    return float(taus[i]), float(cs[j]), ""
