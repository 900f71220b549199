"""meshio round trips: write small VTU / VTM / XDMF series, import, sample; bad input."""
import json
from pathlib import Path

import meshio
import numpy as np
import pytest

from flowfields import open_dataset
from flowfields.dataset import DatasetError
from flowfields.importer import import_series

NU = 1e-3
NX, NY, NZ = 6, 8, 4
LX, LZ, H = 3.0, 1.5, 1.0


def channel_mesh(ny=NY, x_nodes=None):
    """Hexahedral channel mesh: uniform x, z; y graded toward both walls (0 … 2H)."""
    xn = np.linspace(0, LX, NX + 1) if x_nodes is None else x_nodes
    s = np.linspace(-1, 1, ny + 1)
    yn = H * (1 + np.tanh(1.5 * s) / np.tanh(1.5))
    zn = np.linspace(0, LZ, NZ + 1)
    X, Y, Z = np.meshgrid(xn, yn, zn, indexing="ij")
    pts = np.column_stack([X.ravel(), Y.ravel(), Z.ravel()])
    nid = np.arange(len(pts)).reshape(len(xn), len(yn), len(zn))
    cells = []
    for i in range(len(xn) - 1):
        for j in range(len(yn) - 1):
            for k in range(len(zn) - 1):
                cells.append([nid[i, j, k], nid[i + 1, j, k], nid[i + 1, j + 1, k], nid[i, j + 1, k],
                              nid[i, j, k + 1], nid[i + 1, j, k + 1], nid[i + 1, j + 1, k + 1], nid[i, j + 1, k + 1]])
    cells = np.array(cells)
    centres = pts[cells].mean(axis=1)
    return pts, cells, centres


def velocity(centres, t):
    """A laminar-like profile u = U(y) with a travelling wiggle in v (known analytically)."""
    y = centres[:, 1]
    ux = 0.05 * y * (2 * H - y) / (H * H) * 1.0
    uy = 0.001 * np.sin(2 * np.pi * centres[:, 0] / LX + t)
    uz = np.zeros_like(y)
    return np.column_stack([ux, uy, uz])


def write_vtu_series(folder: Path, times=(0.0, 0.5, 1.0), multiblock=False, shuffle=False):
    pts, cells, centres = channel_mesh()
    folder.mkdir(parents=True, exist_ok=True)
    files = []
    rng = np.random.default_rng(0)
    for n, t in enumerate(times):
        order = rng.permutation(len(cells)) if shuffle else np.arange(len(cells))
        mesh = meshio.Mesh(pts, [("hexahedron", cells[order])], cell_data={"U": [velocity(centres[order], t)], "p": [np.zeros(len(cells))]})
        if multiblock:
            (folder / f"case_{n}").mkdir(exist_ok=True)
            meshio.write(folder / f"case_{n}" / "internal.vtu", mesh)
            (folder / f"case_{n}.vtm").write_text(
                "<?xml version='1.0'?>\n<VTKFile type='vtkMultiBlockDataSet' version='1.0'>\n<vtkMultiBlockDataSet>\n"
                f"  <DataSet name='internal' file='case_{n}/internal.vtu' />\n</vtkMultiBlockDataSet>\n</VTKFile>\n"
            )
            files.append({"name": f"case_{n}.vtm", "time": t})
        else:
            meshio.write(folder / f"snap_{n}.vtu", mesh)
            files.append({"name": f"snap_{n}.vtu", "time": t})
    ext = "vtm" if multiblock else "vtu"
    series = folder / f"case.{ext}.series"
    series.write_text(json.dumps({"file-series-version": "1.0", "files": files}))
    return series, centres


def expected_u_tau():
    # dU/dy at the wall = 0.05·2/H; the first-cell estimate ⟨u⟩(y1)/y1 = 0.05(2H − y1)/H²
    _, _, centres = channel_mesh()
    y1 = np.unique(np.round(centres[:, 1], 12))[0]
    return np.sqrt(NU * 0.05 * (2 * H - y1) / H**2)


@pytest.mark.parametrize("multiblock,shuffle", [(False, False), (True, True)])
def test_vtu_series_round_trip(tmp_path, multiblock, shuffle):
    series, centres = write_vtu_series(tmp_path / "raw", multiblock=multiblock, shuffle=shuffle)
    ds = open_dataset(import_series(series, tmp_path / "ds", nu=NU, provenance={"case": "test"}, progress=False))
    ut = expected_u_tau()
    assert ds.meta["provenance"]["u_tau"] == pytest.approx(ut, rel=1e-6)
    assert ds.re_tau == pytest.approx(ut * H / NU, rel=1e-6)
    assert ds.meta["provenance"]["case"] == "test"
    np.testing.assert_allclose(ds.times, np.array([0, 0.5, 1.0]) * ut * ut / NU)
    # lower half kept (centres up to and including the first at/above the centreline)
    assert ds.y[-1] >= ds.re_tau * 0.99 and len(ds.y) == NY // 2 + 1
    # sample at a cell centre of the lower half at the second snapshot: raw value / u_τ
    c = centres[np.argsort(centres[:, 1])][len(centres) // 4]
    c = centres[(np.abs(centres[:, 1] - c[1]) < 1e-12)][0]
    p = c * ut / NU  # the mesh starts at x = z = 0 and the wall at y = 0
    got = ds.velocity([p], ds.times[1])[0]
    np.testing.assert_allclose(got, velocity(c[None], 0.5)[0] / ut, rtol=1e-5, atol=1e-6)


def test_int16_storage_keeps_values_within_quantization(tmp_path):
    series, _ = write_vtu_series(tmp_path / "raw")
    a = open_dataset(import_series(series, tmp_path / "f32", nu=NU, progress=False))
    b = open_dataset(import_series(series, tmp_path / "i16", nu=NU, dtype="int16", progress=False))
    assert b.data.dtype == np.int16
    err = np.abs(a.snapshot(1) - b.snapshot(1)).max()
    assert err <= b.meta["storage"]["max_quantization_error_plus"] * 1.01


def test_xdmf_time_series(tmp_path):
    pts, cells, centres = channel_mesh()
    f = tmp_path / "series.xdmf"
    with meshio.xdmf.TimeSeriesWriter(f, data_format="XML") as w:
        w.write_points_cells(pts, [("hexahedron", cells)])
        for t in (0.0, 0.25):
            w.write_data(t, cell_data={"U": [velocity(centres, t)]})
    ds = open_dataset(import_series(f, tmp_path / "ds", nu=NU, progress=False))
    assert ds.n_snapshots == 2
    assert ds.re_tau == pytest.approx(expected_u_tau() * H / NU, rel=1e-6)


def test_missing_snapshot_is_named(tmp_path):
    series, _ = write_vtu_series(tmp_path / "raw")
    (tmp_path / "raw" / "snap_1.vtu").unlink()
    with pytest.raises(DatasetError, match="snap_1.vtu"):
        import_series(series, tmp_path / "ds", nu=NU, progress=False)


def test_corrupt_snapshot_is_named(tmp_path):
    series, _ = write_vtu_series(tmp_path / "raw")
    (tmp_path / "raw" / "snap_2.vtu").write_text("<VTKFile> garbage")
    with pytest.raises(DatasetError, match="snap_2.vtu.*cannot be read"):
        import_series(series, tmp_path / "ds", nu=NU, progress=False)


def test_nan_values_are_refused(tmp_path):
    pts, cells, centres = channel_mesh()
    u = velocity(centres, 0)
    u[5, 0] = np.nan
    meshio.write(tmp_path / "one.vtu", meshio.Mesh(pts, [("hexahedron", cells)], cell_data={"U": [u]}))
    with pytest.raises(DatasetError, match=r"one.vtu.*NaN"):
        import_series(tmp_path / "one.vtu", tmp_path / "ds", nu=NU, progress=False)


def test_non_uniform_x_is_not_a_channel(tmp_path):
    xn = np.concatenate([[0.0], np.cumsum(np.linspace(0.3, 0.7, NX))])
    pts, cells, centres = channel_mesh(x_nodes=xn)
    meshio.write(tmp_path / "bad.vtu", meshio.Mesh(pts, [("hexahedron", cells)], cell_data={"U": [velocity(centres, 0)]}))
    with pytest.raises(DatasetError, match="x spacing is not uniform"):
        import_series(tmp_path / "bad.vtu", tmp_path / "ds", nu=NU, progress=False)


def test_unstructured_mesh_is_refused(tmp_path):
    pts, cells, centres = channel_mesh()
    keep = np.arange(len(cells)) != 7  # one cell missing: not a tensor product
    meshio.write(tmp_path / "holey.vtu", meshio.Mesh(pts, [("hexahedron", cells[keep])], cell_data={"U": [velocity(centres[keep], 0)]}))
    with pytest.raises(DatasetError, match="tensor-product"):
        import_series(tmp_path / "holey.vtu", tmp_path / "ds", nu=NU, progress=False)


def test_series_with_differing_grids_is_refused(tmp_path):
    series, _ = write_vtu_series(tmp_path / "raw")
    pts, cells, centres = channel_mesh(ny=NY + 2)
    meshio.write(tmp_path / "raw" / "snap_2.vtu", meshio.Mesh(pts, [("hexahedron", cells)], cell_data={"U": [velocity(centres, 1.0)]}))
    with pytest.raises(DatasetError, match="snap_2.vtu: grid differs"):
        import_series(series, tmp_path / "ds", nu=NU, progress=False)


def test_missing_velocity_field_lists_available_fields(tmp_path):
    pts, cells, centres = channel_mesh()
    meshio.write(tmp_path / "p.vtu", meshio.Mesh(pts, [("hexahedron", cells)], cell_data={"p": [np.zeros(len(cells))]}))
    with pytest.raises(DatasetError, match=r"no velocity field 'U'.*'p'"):
        import_series(tmp_path / "p.vtu", tmp_path / "ds", nu=NU, progress=False)


def test_dataset_without_metadata_is_refused(tmp_path):
    series, _ = write_vtu_series(tmp_path / "raw")
    path = import_series(series, tmp_path / "ds", nu=NU, progress=False)
    (path / "meta.json").unlink()
    with pytest.raises(DatasetError, match="no meta.json"):
        open_dataset(path)
    with pytest.raises(DatasetError, match="not found"):
        open_dataset(tmp_path / "nowhere")
