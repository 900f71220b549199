"""Settling of composite grains in still water (seed 000 §4.1)."""
import math

import pytest

from saltation import settling, shapes


def test_haider_levenspiel_sphere_limit_and_shape_effect():
    # ψ = 1 close to the standard sphere curve (Yen) at Re 1-1000
    for re in (1.0, 10.0, 100.0, 1000.0):
        assert settling.haider_levenspiel_cd(re, 1.0) == pytest.approx(settling.yen_cd(re), rel=0.2)
    assert settling.terminal_haider_levenspiel(2e-3, 0.6) < settling.terminal_haider_levenspiel(2e-3, 1.0)


@pytest.mark.parametrize("axes", [(1.6e-3, 1.36e-3, 0.54e-3), (2.6e-3, 1.2e-3, 1.0e-3)])
def test_composites_settle_slower_than_volume_equivalent_sphere(axes):
    comp = shapes.build(*axes)
    res = settling.terminal_velocity(comp, duration=40.0, quat=(math.cos(0.3), math.sin(0.3), 0, 0))
    assert res["steady"] < 1e-2  # reached its terminal velocity
    w_sphere = settling.terminal_sphere_yen(comp.volume_equivalent_diameter)
    assert 0.3 * w_sphere < res["w_m_s"] < w_sphere
    # equal component spheres in a uniform slip: no torque, the orientation is neutral
    assert res["tilt"][-1] == pytest.approx(res["tilt"][0], abs=1e-6)
