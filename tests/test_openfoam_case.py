"""Tests of the OpenFOAM channel-case writer (flowfields.openfoam / flowfields.generate).

The test marked `openfoam` runs a tiny case through blockMesh → pimpleFoam → foamToVTK and
is skipped when OpenFOAM is not installed.
"""
import json
import re
import shutil
import sys
import types

import numpy as np
import pytest

from flowfields import openfoam as of
from flowfields.generate import ChannelParams, run_channel_les

needs_openfoam = pytest.mark.skipif(
    shutil.which("pimpleFoam") is None or shutil.which("blockMesh") is None
    or shutil.which("foamToVTK") is None,
    reason="OpenFOAM (pimpleFoam, blockMesh, foamToVTK) not on PATH",
)


# ---------------------------------------------------------------- mean profile, Ubar


def test_reichardt_limits():
    # viscous sublayer: u+ = y+ ; log layer: slope 1/kappa
    yp = np.array([0.01, 0.1, 0.5])
    assert np.allclose(of.reichardt_uplus(yp), yp, rtol=0.02)
    u1, u2 = of.reichardt_uplus([300.0, 3000.0])
    assert (u2 - u1) / np.log(10.0) == pytest.approx(1 / 0.41, rel=0.01)
    assert of.reichardt_uplus(0.0) == 0.0


@pytest.mark.parametrize("re_tau, ub_dns", [(180, 15.7), (395, 17.5), (590, 18.6)])
def test_bulk_velocity_matches_dns(re_tau, ub_dns):
    # Moser, Kim & Mansour (1999) channel DNS: Re_b = 5600, 13750, 21950 (2h based).
    assert of.bulk_velocity_plus(re_tau) == pytest.approx(ub_dns, rel=0.03)


def test_bulk_velocity_si_units():
    ub = of.bulk_velocity(395, 2e-5, 1.0)
    assert ub == pytest.approx(of.bulk_velocity_plus(395) * 395 * 2e-5)
    p = ChannelParams()
    assert p.ubar == pytest.approx(ub)
    assert p.u_tau == pytest.approx(0.0079)


# ---------------------------------------------------------------- grading


@pytest.mark.parametrize("ny, re_tau, yplus", [(64, 395, 0.8), (64, 395, 0.5), (110, 590, 0.5),
                                                (12, 395, 1.0), (40, 180, 1.0)])
def test_grading_puts_first_cell_at_requested_yplus(ny, re_tau, yplus):
    h = 0.028
    E = of.wall_grading(ny // 2, re_tau, yplus, h)
    yf = of.wall_normal_faces(ny, h, E)
    assert len(yf) == ny + 1
    assert yf[0] == 0.0 and yf[-1] == pytest.approx(2 * h)
    assert yf[ny // 2] == pytest.approx(h)
    first_centre_plus = 0.5 * yf[1] * re_tau / h
    assert first_centre_plus == pytest.approx(yplus, rel=1e-9)
    # symmetric about the centre line, and last/first cell ratio is blockMesh's expansion
    dy = np.diff(yf)
    assert np.allclose(dy, dy[::-1], rtol=1e-9)
    assert dy[ny // 2 - 1] / dy[0] == pytest.approx(E, rel=1e-9)
    assert np.all(np.diff(dy[: ny // 2]) > 0)


def test_grading_rejects_first_cell_coarser_than_uniform():
    with pytest.raises(ValueError, match="first_cell_yplus"):
        of.wall_grading(8, 395, 30.0)


def test_block_mesh_dict_grading(tmp_path):
    E = of.wall_grading(32, 395, 0.8)
    of.write_block_mesh_dict(tmp_path, lx=4, lz=2, h=1, nx=48, ny=64, nz=48, expansion=E)
    text = (tmp_path / "system" / "blockMeshDict").read_text()
    gradings = [float(g) for g in re.findall(r"simpleGrading \(1 ([0-9.eE+-]+) 1\)", text)]
    assert gradings[0] == pytest.approx(E, rel=1e-10)
    assert gradings[1] == pytest.approx(1 / E, rel=1e-10)
    assert text.count("(48 32 48)") == 2
    for a, b in of.CYCLIC_PAIRS:
        assert re.search(rf"{a}\s*{{\s*type\s+cyclic;\s*neighbourPatch\s+{b};", text)
    assert re.search(r"bottomWall\s*{\s*type\s+wall;", text)
    assert re.search(r"topWall\s*{\s*type\s+wall;", text)


def test_cell_centres_and_volumes():
    E = of.wall_grading(6, 395, 1.0)
    c = of.cell_centres(4.0, 2.0, 1.0, 8, 12, 8, E)
    v = of.cell_volumes(4.0, 2.0, 1.0, 8, 12, 8, E)
    assert c.shape == (768, 3) and v.shape == (768,)
    assert v.sum() == pytest.approx(4.0 * 2.0 * 2.0)
    # blockMesh order: lower block first, x fastest
    assert c[0, 1] * 395 == pytest.approx(1.0)
    assert c[1, 0] - c[0, 0] == pytest.approx(0.5)
    assert np.all(c[: 768 // 2, 1] < 1.0) and np.all(c[768 // 2:, 1] > 1.0)


# ---------------------------------------------------------------- dictionaries


def test_write_channel_case_writes_all_dictionaries(tmp_path):
    p = ChannelParams(nprocs=2)
    of.write_channel_case(tmp_path, lx=p.lx, lz=p.lz, h=p.h, nx=p.nx, ny=p.ny, nz=p.nz,
                          expansion=p.expansion, nu=p.nu, ubar=p.ubar, end_time=p.end_time,
                          write_interval=p.snapshot_interval, delta_t=0.01, max_courant=0.5,
                          max_delta_t=p.viscous_time, nprocs=p.nprocs)
    for rel in ("system/blockMeshDict", "system/controlDict", "system/fvSchemes",
                "system/fvSolution", "system/decomposeParDict", "constant/transportProperties",
                "constant/turbulenceProperties", "constant/fvOptions"):
        assert (tmp_path / rel).is_file(), rel
    turb = (tmp_path / "constant/turbulenceProperties").read_text()
    assert re.search(r"LESModel\s+WALE;", turb) and re.search(r"delta\s+cubeRootVol;", turb)
    fvopt = (tmp_path / "constant/fvOptions").read_text()
    assert "meanVelocityForce" in fvopt
    ubar = float(re.search(r"Ubar\s+\(([0-9.eE+-]+) 0 0\)", fvopt).group(1))
    assert ubar == pytest.approx(p.ubar, rel=1e-10)
    ctrl = (tmp_path / "system/controlDict").read_text()
    wi = float(re.search(r"writeInterval\s+([0-9.eE+-]+);", ctrl).group(1))
    assert wi * p.u_tau**2 / p.nu == pytest.approx(4.0, rel=1e-6)  # Δt+ = 4
    assert re.search(r"writeControl\s+adjustableRunTime;", ctrl)
    assert re.search(r"application\s+pimpleFoam;", ctrl)
    nu = float(re.search(r"nu\s+([0-9.eE+-]+);", (tmp_path / "constant/transportProperties").read_text()).group(1))
    assert nu == pytest.approx(2e-5)
    schemes = (tmp_path / "system/fvSchemes").read_text()
    assert re.search(r"default\s+backward;", schemes)
    assert re.search(r"div\(phi,U\)\s+Gauss linear;", schemes)
    assert "numberOfSubdomains 2;" in (tmp_path / "system/decomposeParDict").read_text()


def test_lust_scheme_option(tmp_path):
    of.write_fv_schemes(tmp_path, "LUST")
    assert "Gauss LUST grad(U)" in (tmp_path / "system/fvSchemes").read_text()
    with pytest.raises(ValueError, match="convection"):
        of.write_fv_schemes(tmp_path, "upwind")


def test_velocity_field_roundtrip(tmp_path):
    U = np.random.default_rng(1).normal(size=(20, 3))
    path = of.write_velocity_field(tmp_path, U)
    back = of.read_ascii_internal_vector_field(path)
    assert np.allclose(back, U, rtol=1e-8)
    text = path.read_text()
    assert re.search(r"bottomWall\s*{\s*type\s+noSlip;", text)
    for a, _b in of.CYCLIC_PAIRS:
        assert re.search(rf"{a}\s*{{\s*type\s+cyclic;", text)


def test_perturbed_initial_field_holds_bulk_velocity():
    p = ChannelParams(nx=16, ny=24, nz=16, first_cell_yplus=1.0)
    c = of.cell_centres(p.lx, p.lz, p.h, p.nx, p.ny, p.nz, p.expansion)
    v = of.cell_volumes(p.lx, p.lz, p.h, p.nx, p.ny, p.nz, p.expansion)
    U = of.perturbed_channel_velocity(c, v, lx=p.lx, lz=p.lz, h=p.h, nu=p.nu, re_tau=p.re_tau,
                                      ubar=p.ubar, seed=3)
    assert (U[:, 0] * v).sum() / v.sum() == pytest.approx(p.ubar, rel=0.01)
    assert np.abs(U[:, 2]).max() > 0.01 * p.ubar  # perturbed, not laminar


# ---------------------------------------------------------------- parameters


@pytest.mark.parametrize("kwargs, name", [
    ({"re_tau": -1}, "re_tau"),
    ({"lx_h": 0}, "lx_h"),
    ({"lz_h": float("nan")}, "lz_h"),
    ({"nx": 1}, "nx"),
    ({"ny": 63}, "ny"),
    ({"nz": 2.5}, "nz"),
    ({"first_cell_yplus": 0}, "first_cell_yplus"),
    ({"first_cell_yplus": 20.0}, "first_cell_yplus"),
    ({"snapshot_interval_tplus": -4}, "snapshot_interval_tplus"),
    ({"n_snapshots": 0}, "n_snapshots"),
    ({"spinup_tplus": 0}, "spinup_tplus"),
    ({"nprocs": 0}, "nprocs"),
    ({"initial": "laminar"}, "initial"),
    ({"nu": 0}, "nu"),
    ({"h": -0.1}, "h"),
    ({"max_courant": 2.0}, "max_courant"),
    ({"convection": "upwind"}, "convection"),
])
def test_bad_parameters_name_the_parameter(kwargs, name):
    with pytest.raises(ValueError, match=name):
        ChannelParams(**kwargs)


def test_params_time_conversion():
    p = ChannelParams(spinup_tplus=300, snapshot_interval_tplus=4, n_snapshots=80)
    assert p.viscous_time == pytest.approx(2e-5 / 0.0079**2)
    assert p.end_time == pytest.approx((300 + 320) * p.viscous_time, rel=1e-6)
    res = p.resolution_plus()
    assert res["first_cell_yplus"] == pytest.approx(0.8)
    assert res["dx_plus"] == pytest.approx(4 * 395 / 48)


@pytest.mark.parametrize("spinup, interval, n", [(650, 4, 80), (300, 4, 80), (2.3456789, 1.1, 3)])
def test_write_times_have_short_names(spinup, interval, n):
    """Every write time must print exactly with OpenFOAM's timePrecision (12), or a
    restart from the spin-up's last time looks for a directory name that doesn't exist."""
    p = ChannelParams(spinup_tplus=spinup, snapshot_interval_tplus=interval, n_snapshots=n)
    for t in [p.spinup_time] + [p.spinup_time + k * p.snapshot_interval for k in range(1, n + 1)]:
        assert float(f"{t:.12g}") == pytest.approx(t, rel=1e-14, abs=0)
        assert len(f"{t:.12g}".replace(".", "").lstrip("0")) <= 11
    assert p.spinup_time == pytest.approx(spinup * p.viscous_time, rel=1e-6)


# ---------------------------------------------------------------- tool errors, importer hand-off


def test_missing_tool_raises_named_error(tmp_path):
    with pytest.raises(of.OpenFOAMError, match="no_such_openfoam_tool_xyz"):
        of.run_tool(["no_such_openfoam_tool_xyz"], tmp_path, "xyz")


def test_generate_hands_series_to_importer(tmp_path, monkeypatch):
    """generate() passes the VTK series, ν, provenance, y_max_plus and dtype on verbatim."""
    from flowfields import generate as gen
    series = tmp_path / "VTK" / "case.vtm.series"
    prov = {"params": {"re_tau": 395.0}}
    monkeypatch.setattr(gen, "run_channel_les", lambda *a, **k: (series, prov))
    calls = {}

    def fake_import_series(src, out, *, nu, provenance, y_max_plus, dtype):
        calls.update(src=src, out=out, nu=nu, provenance=provenance, y_max_plus=y_max_plus,
                     dtype=dtype)
        return out

    fake = types.ModuleType("flowfields.importer")
    fake.import_series = fake_import_series
    monkeypatch.setitem(sys.modules, "flowfields.importer", fake)
    out = gen.generate(ChannelParams(nu=1e-6), tmp_path / "ds", tmp_path / "case",
                       y_max_plus=200.0, dtype="int16")
    assert out == tmp_path / "ds"
    assert calls == dict(src=series, out=tmp_path / "ds", nu=1e-6, provenance=prov,
                         y_max_plus=200.0, dtype="int16")
    with pytest.raises(ValueError, match="dtype"):
        gen.generate(ChannelParams(), tmp_path / "ds", tmp_path / "case", dtype="float16")


# ---------------------------------------------------------------- real OpenFOAM


@pytest.mark.openfoam
@needs_openfoam
def test_failing_tool_names_tool_and_log(tmp_path):
    # blockMesh in an empty directory: no system/ → FOAM FATAL ERROR
    with pytest.raises(of.OpenFOAMError) as err:
        of.run_block_mesh(tmp_path)
    assert "blockMesh" in str(err.value) and str(tmp_path / "log.blockMesh") in str(err.value)


@pytest.mark.openfoam
@needs_openfoam
def test_tiny_case_runs_to_vtk(tmp_path):
    import meshio

    p = ChannelParams(nx=8, ny=12, nz=8, first_cell_yplus=1.0, initial="perturb",
                      spinup_tplus=2.3456789, snapshot_interval_tplus=1.1, n_snapshots=3)
    case = tmp_path / "tiny"
    series, prov = run_channel_les(p, case, command_line="pytest tiny")
    assert series.is_file() and series.name.endswith(".vtm.series")
    entries = json.loads(series.read_text())["files"]
    assert len(entries) == 3
    times = [e["time"] for e in entries]
    assert np.allclose(np.diff(times), p.snapshot_interval, rtol=1e-6)
    vtu = sorted((series.parent).glob("*/internal.vtu"))
    assert len(vtu) == 3
    mesh = meshio.read(vtu[0])
    assert "U" in mesh.cell_data
    U = mesh.cell_data["U"][0]
    assert U.shape == (8 * 12 * 8, 3) and np.isfinite(U).all()
    assert 0.5 * p.ubar < U[:, 0].mean() < 1.5 * p.ubar
    assert "1912" in prov["openfoam_version"] or "OpenFOAM" in prov["openfoam_version"]
    assert prov["command_line"] == "pytest tiny"
    assert json.loads((case / "provenance.json").read_text())["params"]["nx"] == 8
    for log in ("log.blockMesh", "log.pimpleFoam.spinup", "log.pimpleFoam.sampling", "log.foamToVTK"):
        assert (case / log).is_file()
    # a second run into the same case directory refuses unless asked to overwrite
    with pytest.raises(FileExistsError):
        run_channel_les(p, case)
