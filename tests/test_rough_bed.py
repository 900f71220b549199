"""The sand bed inside the LES (SPEC §3 rough bed): porosity profile and Ergun drag,
the OpenFOAM case it writes, the roughness analysis, the sampler in and above the bed
layer, and the refusal of runs whose grains do not fit the dataset's bed."""
import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest

from flowfields import rough_bed as rb
from flowfields.dataset import DatasetError, in_memory_dataset, open_dataset
from flowfields.generate import ChannelParams, generate
from saltation.physics.fluid import BED_TOLERANCE, BedMismatch, check_bed

needs_openfoam = pytest.mark.skipif(
    shutil.which("pimpleFoam") is None or shutil.which("blockMesh") is None or shutil.which("topoSet") is None,
    reason="OpenFOAM (pimpleFoam, blockMesh, topoSet, foamToVTK) not on PATH")


# ---------------------------------------------------------------- porosity and drag
def test_solid_fraction_averages_to_close_packing_and_vanishes_above_the_bed_top():
    spacing = rb.LAYER_SPACING
    # one full layer period deep inside the bed: the close-packed solid fraction π/(3√2)
    assert rb.mean_solid_fraction(-0.5 - 2 * spacing, -0.5 - spacing, n=20001) == pytest.approx(0.74048, abs=2e-4)
    assert rb.solid_fraction(0.0) == pytest.approx(0.0, abs=1e-12)  # the crest
    assert rb.solid_fraction(0.3) == 0.0  # above the bed top: no grains
    assert rb.solid_fraction(-0.5) == pytest.approx(math.pi / (2 * math.sqrt(3)))  # top layer's centre plane
    # monotonic from the centre plane up to the crest
    ys = np.linspace(-0.5, 0.0, 50)
    assert np.all(np.diff(rb.solid_fraction(ys)) < 0)
    # a looser packing scales the profile
    assert rb.solid_fraction(-0.5, porosity=0.4) == pytest.approx(
        math.pi / (2 * math.sqrt(3)) * 0.6 / rb.PHI_HCP)


def test_ergun_coefficients_are_ergun_1952():
    d = 1e-3
    dc, fc = rb.ergun_coefficients(0.4, d)
    assert dc == pytest.approx(150 * 0.36 / (0.064 * 1e-6))
    assert fc == pytest.approx(2 * 1.75 * 0.6 / (0.064 * 1e-3))
    # OpenFOAM's DarcyForchheimer: -(ν d + ½|U| f) U reproduces Ergun's pressure drop
    nu, U = 1e-6, 0.01
    dp_ergun = 150 * nu * 0.36 / (0.064 * d * d) * U + 1.75 * 0.6 / (0.064 * d) * U * U
    assert nu * dc * U + 0.5 * fc * U * U == pytest.approx(dp_ergun)
    assert rb.ergun_coefficients(1.0, d) == (0.0, 0.0)


@pytest.mark.parametrize("bad", [0.1, 0.6, float("nan"), "0.3"])
def test_porosity_out_of_range_is_refused(bad):
    with pytest.raises(ValueError, match="porosity must lie between"):
        rb.check_porosity(bad)


@pytest.mark.parametrize("kwargs, name", [
    ({"bed_d_plus": 2.0}, "bed_d_plus"), ({"bed_d_plus": 500.0}, "bed_d_plus"),
    ({"bed_porosity": 0.7}, "porosity"), ({"bed_depth_d": 0.1}, "bed_depth_d"),
    ({"ny_bed": 2}, "ny_bed"), ({"bed": "gravel"}, "bed must be one of"),
    ({"ny_bed": 4, "bed_depth_d": 3.0}, "raise ny_bed"),
])
def test_bad_rough_bed_parameters_name_the_parameter(kwargs, name):
    with pytest.raises(ValueError, match=name):
        ChannelParams(**{"bed": "porous", **kwargs})


# ---------------------------------------------------------------- the OpenFOAM case
def test_rough_case_writes_bed_blocks_zones_and_ergun_drag(tmp_path):
    from flowfields import openfoam as of

    p = ChannelParams(bed="porous", nx=6, ny=8, nz=4, re_tau=100, first_cell_yplus=1.0, ny_bed=6, initial="perturb")
    of.write_channel_case(tmp_path, lx=p.lx, lz=p.lz, h=p.h, nx=p.nx, ny=p.ny, nz=p.nz, expansion=p.expansion,
                          nu=p.nu, ubar=p.ubar, end_time=1, write_interval=1, delta_t=0.1, max_courant=0.5,
                          max_delta_t=0.1)
    of.write_rough_block_mesh_dict(tmp_path, lx=p.lx, lz=p.lz, h=p.h, b=p.bed_thickness, nx=p.nx, ny=p.ny,
                                   ny_bed=p.ny_bed, nz=p.nz, expansion=p.expansion)
    of.write_bed_topo_set(tmp_path, p.bed_layers(), lx=p.lx, lz=p.lz, h=p.h, b=p.bed_thickness, d=p.grain_diameter)
    of.write_fv_options(tmp_path, p.rough_ubar, p.bed_layers())
    mesh = (tmp_path / "system" / "blockMeshDict").read_text()
    assert mesh.count("hex (") == 4
    assert f"({p.nx} {p.ny_bed} {p.nz}) simpleGrading (1 1 1)" in mesh
    top = 2 * p.bed_thickness + 2 * p.h
    assert f"({p.lx:.12g} {top:.12g} {p.lz:.12g})" in mesh
    topo = (tmp_path / "system" / "topoSetDict").read_text()
    assert topo.count("cellZoneSet") == p.ny_bed
    opts = (tmp_path / "constant" / "fvOptions").read_text()
    assert "meanVelocityForce" in opts and opts.count("DarcyForchheimer") == p.ny_bed
    # the densest layer (the deepest) has the largest Darcy coefficient
    layers = p.bed_layers()
    assert layers[0]["darcy_d"] > layers[-1]["darcy_d"] > 0
    assert p.grain_diameter == pytest.approx(p.bed_d_plus * p.nu / p.u_tau)


@needs_openfoam
@pytest.mark.openfoam
def test_tiny_rough_bed_les_runs_and_imports_with_the_bed_top_at_zero(tmp_path):
    p = ChannelParams(bed="porous", nx=8, ny=12, nz=8, re_tau=120, first_cell_yplus=1.0, spinup_tplus=60,
                      snapshot_interval_tplus=2, n_snapshots=2, ny_bed=6, bed_d_plus=19.5, initial="perturb")
    out = generate(p, tmp_path / "ds", tmp_path / "case")
    ds = open_dataset(out)
    prov = ds.meta["provenance"]
    assert ds.bed["kind"] == "porous"
    assert ds.y[0] < 0 < ds.y[-1]  # cells inside the layer and above the bed top
    assert ds.y_floor == pytest.approx(-ds.bed["d_plus"] * p.bed_depth_d, rel=1e-6)
    # u* is the momentum balance at the bed top: the mean driving gradient times the depth
    assert prov["bed"]["u_tau_source"].startswith("momentum balance at the bed top")
    assert ds.bed["d_plus"] == pytest.approx(prov["bed"]["d_plus_measured"])
    assert len(prov["spinup_check"]["ubar_correction"]) == 2
    assert 0.5 <= prov["spinup_check"]["ubar_correction"][0]["factor"] <= 2.0
    # the bed is slower than the flow above it
    u = ds.snapshot(1)[..., 0].mean(axis=(0, 2))
    assert u[0] < 0.2 * u[-1]


def test_a_failed_openfoam_tool_names_its_log(tmp_path):
    from flowfields import openfoam as of

    with pytest.raises(of.OpenFOAMError, match="log"):
        of.run_tool(["false"], tmp_path, "false")


# ---------------------------------------------------------------- roughness analysis
def test_roughness_fit_recovers_a_synthetic_rough_profile():
    d_plus, y_d, du = 19.5, 4.0, 5.0
    y = np.geomspace(1.0, 400.0, 60)
    u = np.log(y + y_d) / rb.KAPPA + rb.B_SMOOTH - du
    fit = rb.roughness_fit(y, u, d_plus, re_tau=395.0)
    assert fit["delta_u_plus"] == pytest.approx(du, abs=0.02)
    assert fit["virtual_origin_plus"] == pytest.approx(y_d, abs=0.1)
    assert fit["log_fit_max_rel_dev"] < 1e-3
    # the equivalent roughness inverts Colebrook's and Nikuradse's laws
    assert rb.colebrook_delta_u(fit["ks_plus_colebrook"]) == pytest.approx(fit["delta_u_plus"])
    assert rb.nikuradse_delta_u(fit["ks_plus_nikuradse"]) == pytest.approx(fit["delta_u_plus"])
    # Colebrook at k_s = d for a sand grain of d+ = 19.5: (1/0.41) ln(1 + 5.85)
    assert rb.colebrook_delta_u(19.5) == pytest.approx(math.log(6.85) / 0.41)


# ---------------------------------------------------------------- sampler in the bed layer
Y_ROUGH = np.array([-8.0, -5.0, -2.0, 1.0, 4.0, 9.0, 16.0, 25.0])
FLOOR = -10.0


def _rough_dataset(fn):
    nx, nz, dx, dz = 5, 4, 3.0, 2.0
    x = dx * (np.arange(nx) + 0.5)
    z = dz * (np.arange(nz) + 0.5)
    X, Yg, Z = np.meshgrid(x, Y_ROUGH, z, indexing="ij")
    u = fn(X, Yg, Z)[None]
    return in_memory_dataset(x, Y_ROUGH, z, u, re_tau=25.0, times_plus=[0.0],
                             meta_extra={"bed": {"kind": "porous", "d_plus": 10.0, "floor_plus": FLOOR}})


def test_rough_sampler_interpolates_across_the_bed_top_and_into_the_layer():
    # a field linear in y is reproduced exactly anywhere between the lowest and highest centres,
    # across the bed top (no wall law between the bed top and the first centre above it)
    ds = _rough_dataset(lambda X, Y, Z: np.stack([2.0 + 0.5 * Y, 0.1 * Y, 0 * X], axis=-1))
    for y in (-7.0, -1.0, 0.0, 0.5, 3.0):
        u = ds.velocity([[4.0, y, 3.0]], 0.0)[0]
        assert u[0] == pytest.approx(2.0 + 0.5 * y, abs=1e-6)
        assert u[1] == pytest.approx(0.1 * y, abs=1e-6)
    # below the lowest centre: linear to zero at the floor (no u+ = y+ sublayer law in a bed)
    u_low = ds.velocity([[4.0, Y_ROUGH[0], 3.0]], 0.0)[0]
    mid = 0.5 * (Y_ROUGH[0] + FLOOR)
    np.testing.assert_allclose(ds.velocity([[4.0, mid, 3.0]], 0.0)[0], 0.5 * u_low, atol=1e-6)
    np.testing.assert_allclose(ds.velocity([[4.0, FLOOR, 3.0]], 0.0)[0], 0.0, atol=1e-9)
    g = ds.gradient([[4.0, mid, 3.0]], 0.0)[0]
    assert g[0, 1] == pytest.approx(u_low[0] / (Y_ROUGH[0] - FLOOR))
    with pytest.raises(ValueError, match=r"\[-10, 25\]"):
        ds.velocity([[4.0, FLOOR - 1.0, 3.0]], 0.0)


def test_a_grain_dipping_below_the_bed_top_sees_the_pore_flow_for_its_lift():
    from saltation.physics.fluid import fluid_at_grain

    ds = _rough_dataset(lambda X, Y, Z: np.stack([np.where(Y > 0, 3.0 + 0.4 * Y, 0.3 * (Y + 10.0) / 10.0), 0 * X,
                                                  0 * X], axis=-1))
    re_star = 10.0
    uf, grad, dudt, vort = np.zeros(3), np.zeros((3, 3)), np.zeros(3), np.zeros(3)
    top, bot = np.zeros(3), np.zeros(3)
    # centre 0.2 d above the bed top: its bottom is 0.3 d = 3 wall units inside the layer
    fluid_at_grain(ds.arrays, re_star, 0.4, 0.2, 0.3, 0.0, True, uf, grad, dudt, vort, top, bot)
    expected_bot = np.interp(-3.0, Y_ROUGH, np.where(Y_ROUGH > 0, 3.0 + 0.4 * Y_ROUGH, 0.3 * (Y_ROUGH + 10) / 10))
    assert bot[0] == pytest.approx(expected_bot, rel=1e-6)
    assert 0.0 < bot[0] < top[0]


def test_smooth_dataset_keeps_the_viscous_sublayer_law():
    ds = open_dataset("channel395")
    a = ds.arrays
    assert a.y_floor == 0.0 and a.sublayer_slope == 1.0 and ds.bed is None


# ---------------------------------------------------------------- runs that do not fit the bed
class _Fake:
    path = "fake_ds"

    def __init__(self, bed):
        self.bed = bed


def test_run_outside_the_bed_grain_tolerance_is_refused_naming_the_command():
    ds = _Fake({"kind": "porous", "d_plus": 19.5, "floor_plus": -19.5})
    check_bed(ds, 19.5 * (1 + 0.99 * BED_TOLERANCE))  # inside: fine
    with pytest.raises(BedMismatch, match=r"Re\* = u\* d/nu = 30.00.*saltation flow generate --bed porous --bed-d-plus 30.0"):
        check_bed(ds, 30.0)
    with pytest.raises(BedMismatch, match="smooth"):
        check_bed(ds, 19.5, bed="smooth")


def test_a_smooth_dataset_used_as_rough_is_refused():
    with pytest.raises(BedMismatch, match="no bed metadata.*--bed porous"):
        check_bed(_Fake(None), 17.5, bed="rough")
    with pytest.raises(ValueError, match="flow.bed"):
        check_bed(_Fake(None), 17.5, bed="gravel")


def test_a_case_over_the_smooth_dataset_declared_rough_fails_before_any_work(tmp_path):
    import saltation
    from saltation.case.schema import CaseError

    case = {"particle": {"diameter": 0.69e-3}, "fluid": {},
            "flow": {"source": "les", "dataset": "channel395", "tau_ratio": 1.79, "bed": "rough"},
            "run": {"n_particles": 2, "duration": 0.01}}
    with pytest.raises((BedMismatch, CaseError), match="no bed metadata"):
        saltation.run(case, out=tmp_path / "r", progress=False)


def test_bad_bed_metadata_names_the_key(tmp_path):
    src = open_dataset("channel395").path
    dst = tmp_path / "ds"
    shutil.copytree(src, dst)
    meta = json.loads((dst / "meta.json").read_text())
    meta["bed"] = {"kind": "porous", "d_plus": -3}
    (dst / "meta.json").write_text(json.dumps(meta))
    with pytest.raises(DatasetError, match="bed.d_plus"):
        open_dataset(dst)


def test_a_diverged_solver_log_is_found_with_its_line(tmp_path):
    from flowfields import openfoam as of

    log = tmp_path / "log.pimpleFoam"
    log.write_text("Time = 1\nCourant Number mean: 0.1 max: 0.4\nTime = 2\nCourant Number mean: 3 max: 480.2\n")
    assert of.diverged_line(log)[0] == 4
    log.write_text("Time = 1\nsmoothSolver:  Solving for Ux, Initial residual = nan, Final residual = nan\n")
    assert of.diverged_line(log)[0] == 2
    log.write_text("Time = 1\nCourant Number mean: 0.1 max: 0.4\n")
    assert of.diverged_line(log) is None


def test_a_sweep_file_keeps_a_shipped_dataset_name(tmp_path):
    from saltation.studies.sweep import load_sweep

    f = tmp_path / "s.toml"
    f.write_text('[particle]\ndiameter = 0.69e-3\n[flow]\nsource = "les"\ndataset = "channel395"\n'
                 '[run]\nn_particles = 4\nduration = 0.01\n[sweep]\ntau_ratio = [1.79, 2.43]\n')
    sw = load_sweep(f)
    assert all(c.tables["flow"]["dataset"] == "channel395" for c in sw.cases)


def test_the_cli_refuses_a_bed_mismatch_in_one_line(tmp_path, capsys):
    from saltation.cli import main

    case = str(Path(__file__).resolve().parent.parent / "cases" / "default.toml")
    assert main(["run", case, "--set", "flow.bed=rough", "--out", str(tmp_path / "r"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and err.startswith("saltation: error: flow.bed = \"rough\"")
    assert "saltation flow generate --bed porous" in err


def test_the_cli_names_a_bad_generate_parameter_in_one_line(tmp_path, capsys):
    from saltation.cli import main

    assert main(["flow", "generate", "--out", str(tmp_path / "d"), "--work-dir", str(tmp_path / "c"), "--bed", "porous",
                 "--bed-porosity", "0.9"]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "porosity must lie between" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "c" / "system").exists()  # refused before any OpenFOAM work
