"""Settling of composite grains in still water (seed 000 §4.1)."""
import math

import pytest

from saltation.grains import shapes
from saltation.studies import settling


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


TILT = (math.cos(0.35), math.sin(0.35) * 0.6, 0.0, math.sin(0.35) * 0.8)  # ≈ 40° off both axes


@pytest.mark.parametrize("axes", [(1.6e-3, 1.36e-3, 0.54e-3), (2.6e-3, 1.2e-3, 1.0e-3)])
def test_wake_shielding_turns_the_largest_projection_across_the_fall(axes):
    # seed 000 §3: disks and rods released tilted fall with their largest projection normal
    # to the fall velocity. Without the wake model, equal spheres in a uniform slip feel no
    # torque and the tilt is neutral; with it the leading end carries more drag.
    comp = shapes.build(*axes)
    off = settling.terminal_velocity(comp, duration=40.0, quat=TILT, wake_shielding=False)
    assert off["tilt"][-1] == pytest.approx(off["tilt"][0], abs=1e-6)
    assert off["long_axis"][-1] == pytest.approx(off["long_axis"][0], abs=1e-6)
    on = settling.terminal_velocity(comp, duration=40.0, quat=TILT)
    assert on["long_axis"][0] > 0.5  # started well tilted
    assert on["long_axis"][-1] < 0.1  # long axis horizontal
    if comp.zingg_class == "disk":
        assert on["tilt"][-1] > 0.95  # and the short axis vertical: flat
    else:
        assert comp.zingg_class == "rod"
    # broadside no sphere is behind another: the terminal velocity is the shield-free one
    # of the same orientation, within a few per cent of the tilted grain's
    assert on["w_m_s"] == pytest.approx(off["w_m_s"], rel=0.05)
