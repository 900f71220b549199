"""``saltation analyze`` on small synthetic run and sweep directories (no simulation)."""
from __future__ import annotations

import json
import re
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from test_diffusion import hopping_grains  # noqa: E402

from saltation.analysis import reference as ref  # noqa: E402
from saltation.analysis.report import analyze  # noqa: E402
from saltation.cli import main  # noqa: E402


def make_run(path: Path, n=30, n_samples=1500, concentration=0.0004, tau_ratio=1.79, seed=1):
    """A run directory whose tracks are hopping grains (τ = 4 d/u*) and whose jumps
    table lists those hops; summary.json in the run loop's layout."""
    path.mkdir(parents=True)
    tracks, tau = hopping_grains(n=n, n_samples=n_samples, seed=seed)
    for c in ("u", "v", "w", "spin_x", "spin_y", "spin_z"):
        tracks[c] = 0.0
    tracks["u"] = tracks.groupby("particle")["x"].diff().fillna(0.0) / 0.08
    tracks.to_parquet(path / "tracks.parquet")
    rng = np.random.default_rng(seed)
    m = 20 * n
    dur = rng.uniform(0.8, 1.2, m) * tau
    u = rng.normal(5, 1.5, m)
    jumps = pd.DataFrame({"particle": np.repeat(np.arange(n), 20), "jump": np.tile(np.arange(20), n),
                          "t_start": 0.0, "length": u * dur, "height": 2.0, "duration": dur, "velocity": u})
    jumps.to_parquet(path / "jumps.parquet")
    summary = {"status": "completed", "n_particles": n, "concentration": concentration, "tau_ratio": tau_ratio,
               "tau_star": 0.032 * tau_ratio, "simulated_time_s": 3.0, "simulated_time_particle": n_samples * 0.08,
               "jumps": {"count": 10 * n, "H_mean": 2.0, "H_std": 0.0, "L_mean": 20.0, "L_std": 6.0,
                         "U_mean": 5.0, "U_std": 1.5},
               "collisions": {"particle_particle": 3 * n, "bed": 20 * n, "per_particle": 20.0},
               "timing": {"wall_s": 10.0 * n, "free_flight_s": 8.0 * n, "bed_s": 1.0, "particle_collisions_s": 1.0,
                          "threads": 1, "compile_s": 0.1},
               "particle_steps_per_s": 1e6}
    (path / "summary.json").write_text(json.dumps(summary))
    return path


def test_analyze_run_directory(tmp_path):
    run = make_run(tmp_path / "run")
    res = analyze(run)
    out = run / "analysis"
    for f in ("jump_stats.csv", "diffusion.csv", "crossover.csv", "variance_curves.csv", "variance.png",
              "jump_distributions.png", "collisions_cost.csv", "report.html"):
        assert (out / f).exists(), f
    d = res["diffusion"]
    # the windows come from the crossover (τ = 4 d/u* hops); T_J of jumps.parquet is the cross-check
    assert d["windows_from"] == {"local": "crossover", "intermediate": "crossover"}
    assert d["jump_duration_from"] == "jumps.parquet" and d["crossover"]["t_c"] == pytest.approx(4.0, rel=0.2)
    assert d["local"]["gamma_x"] == pytest.approx(1.0, abs=0.08)
    js = pd.read_csv(out / "jump_stats.csv").set_index("quantity")
    assert js.loc["T", "n"] == 10 * 30  # the first 10 of each grain's 20 jumps are dropped
    page = (out / "report.html").read_text()
    assert page.count("data:image/png;base64,") >= 3
    assert not re.search(r'src="(?!data:)', page)  # self-contained: no external images


def test_analyze_sweep_directory_side_by_side_with_paper(tmp_path):
    sweep = tmp_path / "sweep"
    make_run(sweep / "cases" / "a", concentration=0.0004, tau_ratio=1.79, seed=1)
    make_run(sweep / "cases" / "b", n=40, concentration=0.0026, tau_ratio=1.79, seed=2)
    # too short a record for the intermediate range: must show up as a note, never a NaN
    make_run(sweep / "cases" / "c", concentration=0.0052, tau_ratio=2.43, n_samples=150, seed=3)
    vdir = tmp_path / "validation"
    vdir.mkdir()
    pd.DataFrame({"tau_ratio": [1.79], "count": [100], "H_mean": [1.0]}).to_csv(vdir / "validation.csv", index=False)
    res = analyze(sweep, validation=vdir)
    out = sweep / "analysis"
    for f in ("cases.csv", "gamma_vs_paper.csv", "cost_vs_paper.csv", "fig5_jumps_vs_concentration.png",
              "fig6_velocity.png", "fig7_collisions_cost.png", "fig8_variance.png", "fig9_gamma.png", "report.html"):
        assert (out / f).exists(), f
    gv = res["tables"]["gamma_vs_paper"]
    assert len(gv) == 3 * 4
    row = gv[(gv["case"] == "b") & (gv["table"] == 5)].iloc[0]  # intermediate γx, τ 1.79, C 0.26 %
    assert row["gamma_paper"] == ref.GAMMA[("intermediate", "x")][1.79][3] == 0.75
    assert row["difference"] == pytest.approx(row["gamma_ours"] - 0.75)
    short = gv[(gv["case"] == "c") & (gv["range"] == "intermediate")]
    assert short["gamma_ours"].isna().all() and short["note"].str.contains("too short").all()
    cv = res["tables"]["cost_vs_paper"]
    assert cv["paper_N"].isna().all() and cv["note"].str.contains("no paper N").all()  # 30-40 grains
    page = (out / "report.html").read_text()
    assert "Table 7" in page and "validation" in page and page.count("data:image/png;base64,") >= 5


def test_match_case():
    assert ref.match_case(1.79, 0.26) == (1.79, 0.26, "")
    assert ref.match_case(1.80, 0.30)[1] == 0.26
    tau, c, why = ref.match_case(2.0, 0.26)
    assert tau is None and "no paper case" in why
    tau, c, why = ref.match_case(1.79, 0.7)
    assert c is None and "nearest 0.52" in why


def test_cli_errors(tmp_path, capsys):
    assert main(["analyze", str(tmp_path / "missing")]) == 2
    assert "not a directory" in capsys.readouterr().err
    (tmp_path / "empty").mkdir()
    assert main(["analyze", str(tmp_path / "empty")]) == 2
    assert "nothing to analyse" in capsys.readouterr().err


# --------------------------------------------------------------------------- tracks files (issue 16)
def test_analyze_tracks_csv_from_the_command_line(tmp_path, capsys):
    """`saltation analyze tracks.csv`: diffusion table, crossover table, variance figure and
    report in <stem>_analysis/ beside the file; the printed and written t_c and γ are those
    of exponents() on the same tracks; SI units converted with --diameter/--time-scale."""
    from test_crossover import hop_tracks

    from saltation.analysis.diffusion import exponents

    tracks, expected = hop_tracks(n=80, n_samples=2500, seed=11)
    tracks.to_csv(tmp_path / "flume.csv", index=False)
    assert main(["analyze", str(tmp_path / "flume.csv")]) == 0
    printed = capsys.readouterr().out
    out = tmp_path / "flume_analysis"
    for f in ("diffusion.csv", "crossover.csv", "variance_curves.csv", "variance.png", "report.html"):
        assert (out / f).exists(), f
    ref_res = exponents(tracks)
    cr = pd.read_csv(out / "crossover.csv").set_index("direction")
    assert cr.loc["x", "t_c"] == pytest.approx(ref_res["crossover"]["t_c"], rel=1e-9)
    assert bool(cr.loc["x", "sets_ranges"]) and not bool(cr.loc["z", "sets_ranges"])
    assert 0.8 * expected < cr.loc["x", "t_c"] < 1.2 * expected
    assert f"t_c = {ref_res['crossover']['t_c']:.3g}" in printed and "T_J not known" in printed
    tab = pd.read_csv(out / "diffusion.csv")
    assert len(tab) == 4 and (tab["windows_from"] == "crossover").all()
    np.testing.assert_allclose(tab["gamma"], ref_res.table["gamma"], rtol=1e-9)
    page = (out / "report.html").read_text()
    assert "data:image/png;base64," in page and "t_c" in page

    si = tracks.assign(t=tracks["t"] * 0.0273, x=tracks["x"] * 0.69e-3, z=tracks["z"] * 0.69e-3)
    si.to_parquet(tmp_path / "si.parquet")
    assert main(["analyze", str(tmp_path / "si.parquet"), "--diameter", "0.00069", "--time-scale", "0.0273",
                 "--out", str(tmp_path / "si_out")]) == 0
    capsys.readouterr()
    tab_si = pd.read_csv(tmp_path / "si_out" / "diffusion.csv")
    np.testing.assert_allclose(tab_si["gamma"], tab["gamma"], atol=0.02)
    assert pd.read_csv(tmp_path / "si_out" / "crossover.csv")["t_c"][0] == pytest.approx(cr.loc["x", "t_c"], rel=0.05)


def test_analyze_tracks_file_errors(tmp_path, capsys):
    pd.DataFrame({"particle": [0, 0], "t": [0.0, 1.0], "x": [0.0, 1.0]}).to_csv(tmp_path / "no_z.csv", index=False)
    assert main(["analyze", str(tmp_path / "no_z.csv")]) == 2
    err = capsys.readouterr().err
    assert "lacks column(s) z" in err and "t (time, d/u*)" in err and "z (spanwise position, unwrapped, d)" in err
    (tmp_path / "notes.txt").write_text("x")
    assert main(["analyze", str(tmp_path / "notes.txt")]) == 2
    assert "not a tracks file" in capsys.readouterr().err
    run = make_run(tmp_path / "run", n_samples=300)
    assert main(["analyze", str(run), "--diameter", "0.00069"]) == 2
    assert "tracks file's units" in capsys.readouterr().err


# --------------------------------------------------------------------------- report figures (issue 16 item 8)
def _capture_figures(monkeypatch):
    from saltation.analysis import report

    figs = {}
    real = report._save

    def keep(fig, path):
        figs[Path(path).name] = [(ax.get_title(), [t.get_text() for t in ax.texts]) for ax in fig.axes]
        return real(fig, path)

    monkeypatch.setattr(report, "_save", keep)
    return figs


def test_run_collisions_panel_names_grain_grain_and_bed(tmp_path, monkeypatch):
    figs = _capture_figures(monkeypatch)
    analyze(make_run(tmp_path / "run", n_samples=300))
    title = figs["collisions_cost.png"][1][0]
    # summary: 3·30 grain–grain collisions → per_particle 20.0 as written by make_run; 20·30 bed impacts → 20 per grain
    assert "grain–grain" in title and "bed" in title and "bed collisions per grain" not in title
    assert "20.0 grain–grain" in title and "20.0 bed" in title


def test_sweep_velocity_figure_says_why_it_is_empty_without_tracks(tmp_path, monkeypatch):
    import warnings

    figs = _capture_figures(monkeypatch)
    sweep = tmp_path / "sweep"
    for name, c in (("a", 0.0004), ("b", 0.0026)):
        (make_run(sweep / "cases" / name, concentration=c, n_samples=300) / "tracks.parquet").unlink()
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)  # matplotlib's "No artists with labels" legend warning
        analyze(sweep)
    texts = figs["fig6_velocity.png"][1][1]
    assert texts and "no tracks.parquet in 2 of 2 case(s)" in texts[0] and "output.tracks = true" in texts[0]
    # with tracks in one case of two the panel is drawn and names the case without them
    sweep2 = tmp_path / "sweep2"
    make_run(sweep2 / "cases" / "a", n_samples=300)
    (make_run(sweep2 / "cases" / "b", concentration=0.0026, n_samples=300) / "tracks.parquet").unlink()
    analyze(sweep2)
    texts = figs["fig6_velocity.png"][1][1]
    assert "no tracks.parquet in 1 of 2 case(s) (b)" in texts[0]
