"""Case files: loading, derived numbers (SPEC §1), overrides, round trip, errors."""

import dataclasses
import math
import tomllib
from pathlib import Path

import pytest

from saltation.case.schema import (
    PAPER_DOMAIN_M,
    Case,
    CaseError,
    dump_toml,
    load_case,
    loads_case,
    parse_overrides,
    resolve_domain,
)

# single-run case files; sweep files (a [sweep] table) are checked in tests/test_sweep.py
CASES = sorted(p for p in (Path(__file__).resolve().parent.parent / "cases").glob("*.toml")
               if "sweep" not in tomllib.loads(p.read_text()))

D = 0.69e-3  # m, the paper's validation grain


def base(**tables):
    """A minimal valid dict case (quartz, d = 0.69 mm, water), with tables replaced/merged."""
    out = {
        "particle": {"diameter": D, "density": 2650.0},
        "fluid": {"density": 1000.0, "viscosity": 1.0e-6},
        "flow": {"source": "loglaw", "tau_ratio": 1.79},
        "run": {"duration": 1.0},
    }
    for name, content in tables.items():
        if content is None:
            out.pop(name, None)
        else:
            out[name] = {**out.get(name, {}), **content}
    return out


def error_of(source, overrides=None) -> str:
    with pytest.raises(CaseError) as info:
        load_case(source, overrides)
    return str(info.value)


# --------------------------------------------------------------------------- shipped cases


def test_shipped_cases_present():
    names = {p.stem for p in CASES}
    assert {"default", "loglaw", "nino_garcia_179", "nino_garcia_187", "nino_garcia_243",
            "nino_garcia_267"} <= names


@pytest.mark.parametrize("path", CASES, ids=lambda p: p.stem)
def test_shipped_case_loads_and_round_trips(path):
    case = load_case(path)
    assert case.run.name == path.stem
    assert 0.01 <= case.dt_particle <= 0.02  # the project's time-step choice
    assert case.n_steps == math.ceil(case.duration / case.dt - 1e-9)
    assert loads_case(dump_toml(case)) == case
    assert load_case(case.to_dict()) == case


@pytest.mark.parametrize("ratio", [1.79, 1.87, 2.43, 2.67])
def test_nino_garcia_cases(ratio):
    case = load_case(CASES[0].parent / f"nino_garcia_{round(ratio * 100)}.toml")
    assert case.flow.source == "les"
    assert case.tau_ratio == ratio
    assert case.flow.tau_c == 0.032
    assert case.particle.diameter == D
    assert case.Rp == pytest.approx(72.92, abs=0.01)
    assert case.n_particles == 20
    # ≥ 110 jumps per grain even at a pessimistic 10 d/u* per jump
    assert case.duration_particle >= 110 * 10
    assert case.collisions.model == "off"


def test_default_and_loglaw_cases():
    default = load_case(CASES[0].parent / "default.toml")
    loglaw = load_case(CASES[0].parent / "loglaw.toml")
    assert default.flow.source == "les" and loglaw.flow.source == "loglaw"
    assert default.tau_ratio == loglaw.tau_ratio == 1.79
    assert 100 <= default.n_particles <= 1000
    assert default.domain is None  # the LES box, resolved by the run loop
    assert loglaw.domain == PAPER_DOMAIN_M


# --------------------------------------------------------------------------- derived numbers


def test_derived_numbers_of_the_validation_grain():
    case = load_case(base())
    g, R, d, nu = 9.81, 1.65, D, 1.0e-6
    assert case.gravity == g
    assert case.R == pytest.approx(R)
    assert case.submerged_specific_gravity == case.R
    # Rp = √(9.81·1.65·0.00069³)/1e-6 = 72.92 (the paper rounds it to 73)
    assert case.Rp == pytest.approx(math.sqrt(g * R * d**3) / nu)
    assert case.Rp == pytest.approx(72.92, abs=0.01)
    assert case.tau_star == 1.79 * 0.032
    assert case.shields_number == case.tau_star
    u_star = math.sqrt(1.79 * 0.032 * g * R * d)
    assert case.shear_velocity == pytest.approx(u_star)
    assert case.shear_velocity == pytest.approx(0.02529, abs=1e-5)
    assert case.re_star == pytest.approx(u_star * d / nu)
    assert case.re_star == pytest.approx(math.sqrt(case.tau_star) * case.Rp)  # SPEC §1
    assert case.re_star == pytest.approx(17.45, abs=0.01)
    assert case.Cm == 0.5
    assert case.alpha == pytest.approx(1 / (1 + 1.65 + 0.5))
    assert case.time_scale == pytest.approx(d / u_star)
    assert case.viscous_length == pytest.approx(nu / u_star)
    assert case.dt_particle == 0.02  # the default (docs/studies/stiffness_dt.md)
    assert case.dt == pytest.approx(0.02 * d / u_star)
    assert case.duration_particle == pytest.approx(1.0 * u_star / d)
    assert case.stokes_response_time == pytest.approx((2.65 + 0.5) * d**2 / (18 * nu))
    assert case.response_time < case.stokes_response_time
    assert case.bed_restitution == 0.65 and case.bed_friction == 0.10  # Schmeeckle 2001


def test_shear_velocity_input_gives_tau_ratio():
    case = load_case(base(flow=None) | {"flow": {"source": "les", "shear_velocity": 0.025}})
    assert case.flow.tau_ratio is None
    assert case.shear_velocity == 0.025
    assert case.tau_star == pytest.approx(0.025**2 / (9.81 * 1.65 * D))
    assert case.tau_ratio == pytest.approx(case.tau_star / 0.032)


def test_still_fluid_uses_settling_velocity_scale():
    case = load_case(base(flow=None) | {"flow": {"source": "still"}})
    assert case.shear_velocity == pytest.approx(math.sqrt(9.81 * 1.65 * D))
    assert case.tau_star == 1.0
    assert case.re_star == pytest.approx(case.Rp)


def test_added_mass_off_removes_cm_from_inertia():
    case = load_case(base(forces={"added_mass": False}))
    assert case.Cm == 0.0
    assert case.alpha == pytest.approx(1 / 2.65)


def test_slope_and_tilt_in_degrees():
    case = load_case(base(flow={"slope": 2.0}, bed={"max_tilt": 25.0}))
    assert case.flow.slope_radians == pytest.approx(math.radians(2.0))
    assert case.bed.max_tilt_radians == pytest.approx(math.radians(25.0))


def test_bed_coefficient_sets():
    assert load_case(base(bed={"coefficients": "tsuji-1987"})).bed_restitution == 0.80
    ng = load_case(base(bed={"coefficients": "nino-garcia"}, flow={"tau_ratio": 2.43}))
    assert ng.bed.coefficients == "nino-garcia-1994"
    assert ng.bed_restitution == pytest.approx(0.75 - 0.25 * 2.43)
    assert ng.bed_friction == 0.89
    user = load_case(base(bed={"restitution": 0.5, "friction": 0.3}))
    assert user.bed.coefficients == "user"
    assert (user.bed_restitution, user.bed_friction) == (0.5, 0.3)


def test_soft_contact_stiffness_and_substeps():
    case = load_case(base(collisions={"model": "soft"}))
    m_eff = 0.5 * 2650.0 * math.pi / 6 * D**3
    v = 10 * case.shear_velocity
    k = case.collision_stiffness
    assert v * math.sqrt(m_eff / k) == pytest.approx(0.01 * D)  # overlap = 1 % of d
    assert case.contact_duration == pytest.approx(math.pi * math.sqrt(m_eff / k))
    assert case.contact_duration / (case.dt / case.contact_substeps) >= 20 - 1e-9
    assert load_case(base(collisions={"model": "off"})).contact_substeps == 1  # contacts off


def test_output_intervals_are_whole_steps():
    case = load_case(base(output={"tracks_interval": 0.0031}))
    assert case.tracks_every == round(0.0031 / case.dt)
    assert case.tracks_interval == pytest.approx(case.tracks_every * case.dt)
    default = load_case(base())
    assert default.tracks_interval == pytest.approx(0.5 * default.time_scale, rel=0.02)
    assert default.vtk_every == round(default.duration / 100 / default.dt)


# --------------------------------------------------------------------------- concentration


H = 0.028
PAPER_BOX = [2 * math.pi * H, math.pi * H, H]


@pytest.mark.parametrize("n, percent", [(1000, 0.04), (99_000, 3.94)])
def test_spec_concentration_check(n, percent):
    case = load_case(base(run={"n_particles": n, "domain": PAPER_BOX}))
    # C = N (π/6) d³ / (Lx Lz H): 0.0397 % and 3.93 %, which the paper rounds to 0.04 / 3.94 %
    assert case.concentration == pytest.approx(n * math.pi / 6 * D**3 / (2 * math.pi**2 * H**3))
    assert 100 * case.concentration == pytest.approx(percent, rel=0.01)


def test_concentration_fills_domain():
    case = resolve_domain(load_case(base(run={"concentration": 0.0394, "domain": PAPER_BOX})))
    assert case.n_particles == pytest.approx(99_000, rel=0.005)
    assert case.run.domain == tuple(PAPER_BOX)
    assert case.concentration == pytest.approx(0.0394, rel=1e-4)


def test_both_number_and_concentration_scale_domain_keeping_aspect():
    case = load_case(base(run={"n_particles": 1000, "concentration": 0.01,
                               "domain": PAPER_BOX}))
    resolved = resolve_domain(case)
    lx, lz, h = resolved.run.domain
    assert lx / lz == pytest.approx(2.0) and lx / h == pytest.approx(2 * math.pi)
    assert resolved.n_particles == 1000
    assert resolved.concentration == pytest.approx(0.01)
    assert resolved.run.concentration is None
    assert resolve_domain(resolved) == resolved
    assert loads_case(dump_toml(resolved)) == resolved


def test_les_box_is_the_default_domain():
    case = load_case(base(flow={"source": "les"}, run={"n_particles": 50}))
    assert case.domain is None
    box = (0.045, 0.022, 0.007)
    resolved = resolve_domain(case, les_box_m=box)
    assert resolved.run.domain == box
    assert resolved.concentration == pytest.approx(50 * math.pi / 6 * D**3 / math.prod(box))
    with pytest.raises(CaseError, match=r"run\.domain.*les_box_m"):
        resolve_domain(case)
    # an explicit domain wins over the LES box
    own = load_case(base(flow={"source": "les"}, run={"n_particles": 50, "domain": PAPER_BOX}))
    assert resolve_domain(own, les_box_m=box).run.domain == tuple(PAPER_BOX)


def test_analytic_source_defaults_to_paper_domain():
    resolved = resolve_domain(load_case(base(run={"concentration": 0.001})))
    assert resolved.run.domain == PAPER_DOMAIN_M
    assert resolved.n_particles == round(0.001 * math.prod(PAPER_DOMAIN_M)
                                         / (math.pi / 6 * D**3))


def test_one_grain_by_default():
    assert load_case(base()).n_particles == 1


# --------------------------------------------------------------------------- overrides


def test_overrides_as_dict_and_strings():
    case = load_case(base(), {"run.seed": 3, "forces.basset": False})
    assert case.run.seed == 3 and case.forces.basset is False
    case = load_case(base(), ["run.seed=4", 'flow.source="les"', "bed.model=packed",
                              "run.domain=[0.1, 0.05, 0.02]", "forces.lift=false"])
    assert case.run.seed == 4
    assert case.flow.source == "les"
    assert case.bed.model == "packed"
    assert case.run.domain == (0.1, 0.05, 0.02)
    assert case.forces.lift is False
    assert load_case(base(), "flow.source=still").flow.source == "still"
    assert load_case(base(), {"run__seed": 5}).run.seed == 5  # keyword-argument form


def test_parse_overrides_types():
    parsed = parse_overrides(["run.seed=3", "flow.tau_ratio=2.43", "flow.source=loglaw",
                              "output.directory=runs/a b"])
    assert parsed == {"run": {"seed": 3}, "flow": {"tau_ratio": 2.43, "source": "loglaw"},
                      "output": {"directory": "runs/a b"}}


def test_override_replaces_the_other_of_a_pair():
    case = load_case(base(), {"flow.shear_velocity": 0.02})
    assert case.flow.tau_ratio is None and case.shear_velocity == 0.02
    case = load_case(base(), ["run.dt=1e-4"])
    assert case.run.dt_particle is None and case.dt == 1e-4
    case = load_case(base(run={"n_particles": 10}), ["run.concentration=0.001"])
    assert case.run.n_particles is None
    case = load_case(base(bed={"restitution": 0.5, "friction": 0.3}),
                     ["bed.coefficients=tsuji-1987"])
    assert case.bed_restitution == 0.80
    case = load_case(base(bed={"restitution": 0.5, "friction": 0.3}), ["bed.restitution=0.6"])
    assert (case.bed_restitution, case.bed_friction) == (0.6, 0.3)


def test_override_of_shipped_case_and_round_trip(tmp_path):
    case = load_case(CASES[0].parent / "nino_garcia_179.toml", ["flow.tau_ratio=2.43"])
    assert case.tau_ratio == 2.43
    path = tmp_path / "config.toml"
    path.write_text(dump_toml(case))
    again = load_case(path)
    assert again == case  # run.name is written, so the stem "config" does not replace it


def test_load_from_case_with_overrides():
    case = load_case(base())
    assert load_case(case) == case
    assert load_case(case, {"run.seed": 9}).run.seed == 9


# --------------------------------------------------------------------------- round trip


def test_round_trip_of_every_key(tmp_path):
    tables = base(
        flow={"source": "les", "dataset": str(tmp_path / "les"), "tau_ratio": None,
              "shear_velocity": 0.021, "tau_c": 0.04, "slope": 1.5, "profile": "composite",
              "roughness": 3.0},
        forces={"drag": True, "lift": False, "magnus": False, "added_mass": True,
                "fluid_acceleration": False, "basset": False, "weight": True,
                "added_mass_coefficient": 0.6, "lift_coefficient": 0.15,
                "magnus_coefficient": 0.5, "basset_window": 16},
        bed={"model": "packed", "restitution": 0.7, "friction": 0.2, "max_tilt": 25.0},
        collisions={"model": "soft", "restitution": 0.8, "friction": 0.3, "stiffness": 5000.0,
                    "tangential_stiffness_ratio": 0.25, "max_overlap": 0.02,
                    "impact_speed": 8.0},
        run={"name": 'odd "name" ünï\n\tx', "n_particles": 200, "duration": 2.5, "dt": 2e-4,
             "seed": 42, "domain": [0.1, 0.05, 0.02], "threads": 4, "release_height": 5.0},
        output={"directory": "runs/here", "tracks": False, "tracks_interval": 0.002,
                "vtk": False, "vtk_interval": 0.05},
    )
    del tables["flow"]["tau_ratio"]
    case = load_case(tables)
    text = dump_toml(case)
    assert tomllib.loads(text) == case.to_dict()
    assert loads_case(text) == case
    assert load_case(case.to_dict()) == case
    assert case.run.name == 'odd "name" ünï\n\tx'


def test_dump_names_every_key_and_derived_values():
    case = load_case(base(flow={"source": "les"}))
    text = dump_toml(case)
    for name in ("particle", "fluid", "flow", "forces", "bed", "collisions", "run", "output"):
        table = getattr(case, name)
        assert f"[{name}]" in text
        for key in table.keys():
            assert f"\n{key} = " in text or f"\n# {key} (absent)" in text
    assert "tau_star = 0.05728" in text
    assert "0.65 from schmeeckle-2001" in text


def test_case_is_frozen():
    case = load_case(base())
    with pytest.raises(dataclasses.FrozenInstanceError):
        case.run = None
    with pytest.raises(dataclasses.FrozenInstanceError):
        case.particle.diameter = 1.0


def test_dataset_path_relative_to_case_file(tmp_path):
    (tmp_path / "sub").mkdir()
    path = tmp_path / "sub" / "c.toml"
    path.write_text('[particle]\ndiameter = 0.69e-3\n[flow]\nsource = "les"\n'
                    'dataset = "../data"\ntau_ratio = 1.79\n[run]\nduration = 1.0\n')
    assert load_case(path).flow.dataset == str(tmp_path / "data")
    # from an override, relative to the working directory
    case = load_case(path, ["flow.dataset=elsewhere"])
    assert case.flow.dataset == str(Path.cwd() / "elsewhere")


# --------------------------------------------------------------------------- errors


def test_unknown_table_suggests_closest():
    msg = error_of(base() | {"partcle": {"diameter": 1e-3}})
    assert "unknown table [partcle]" in msg and "did you mean [particle]" in msg


def test_unknown_key_suggests_closest():
    msg = error_of(base(flow={"tau_ration": 2.0}))
    assert "unknown key flow.tau_ration" in msg and "did you mean flow.tau_ratio" in msg
    msg = error_of(base(), ["run.sed=3"])
    assert "unknown key run.sed" in msg and "run.seed" in msg


def test_top_level_key_points_to_its_table():
    msg = error_of(base() | {"seed": 3})
    assert "'seed'" in msg and "[run]" in msg
    assert "[run] must be a table of keys" in error_of(base() | {"run": 3})


def test_wrong_type_names_key():
    assert "particle.diameter must be a number" in error_of(base(particle={"diameter": "big"}))
    assert "run.seed must be an integer" in error_of(base(run={"seed": 1.5}))
    assert "forces.drag must be true or false" in error_of(base(forces={"drag": 1}))
    assert "run.domain must be a list of three numbers" in error_of(base(run={"domain": [1, 2]}))
    msg = error_of(base(flow={"source": "dns"}))
    assert 'flow.source' in msg and '"les", "loglaw", "still"' in msg
    msg = error_of(base(bed={"coefficients": "schmeckle"}))
    assert "bed.coefficients = 'schmeckle' is not allowed" in msg
    assert 'did you mean "schmeeckle-2001"' in msg


def test_missing_required_keys():
    tables = base()
    del tables["particle"]["diameter"]
    assert "particle.diameter is required" in error_of(tables)
    tables = base()
    del tables["run"]["duration"]
    assert "run.duration is required" in error_of(tables)
    assert "table [run] is required" in error_of(base(run=None))
    tables = base(flow={"source": "les"})
    del tables["flow"]["tau_ratio"]
    msg = error_of(tables)
    assert "flow.tau_ratio or flow.shear_velocity is required" in msg and '"les"' in msg


@pytest.mark.parametrize("tables, text", [
    (base(particle={"diameter": -1e-3}), "particle.diameter = -0.001 is out of range: must be > 0 m"),
    (base(particle={"diameter": 0}), "particle.diameter = 0.0 is out of range"),
    (base(fluid={"viscosity": 0.0}), "fluid.viscosity = 0.0 is out of range: must be > 0"),
    (base(particle={"density": 1000.0}), "particle.density = 1000.0 kg/m³ must exceed fluid.density"),
    (base(particle={"density": 900.0}), "the grain must settle"),
    (base(bed={"restitution": 1.2, "friction": 0.1}), "bed.restitution = 1.2 is out of range: must be >= 0 and <= 1"),
    (base(bed={"restitution": 0.5, "friction": -0.1}), "bed.friction = -0.1 is out of range: must be >= 0"),
    (base(collisions={"restitution": -0.1}), "collisions.restitution = -0.1 is out of range"),
    (base(collisions={"friction": -1}), "collisions.friction = -1.0 is out of range: must be >= 0"),
    (base(run={"duration": 0.0}), "run.duration = 0.0 is out of range: must be > 0 s"),
    (base(run={"duration": -5}), "run.duration = -5.0 is out of range"),
    (base(run={"n_particles": 0}), "run.n_particles = 0 is out of range: must be >= 1"),
    (base(run={"concentration": 3.94}), "run.concentration = 3.94 is out of range: must be > 0 and <= 0.05"),
    (base(flow={"tau_ratio": -1.0}), "flow.tau_ratio = -1.0 is out of range: must be > 0"),
    (base(flow={"slope": 95.0}), "flow.slope = 95.0 is out of range: must be > -90 and < 90 deg"),
    (base(run={"release_height": 0.2}), "run.release_height = 0.2 is out of range: must be >= 0.5 d"),
    (base(forces={"basset_window": 1}), "forces.basset_window = 1 is out of range: must be >= 2"),
])
def test_out_of_range(tables, text):
    assert text in error_of(tables)


def test_both_or_neither_of_exclusive_pairs():
    msg = error_of(base(flow={"shear_velocity": 0.02}))
    assert "flow.tau_ratio and flow.shear_velocity are both given" in msg
    msg = error_of(base(run={"dt": 1e-4, "dt_particle": 0.01}))
    assert "run.dt and run.dt_particle are both given" in msg


def test_time_step_must_resolve_response_time():
    # dt = 5 ms for a grain whose drag response time is ≈ 14 ms: above τ_p/5 = 2.8 ms
    msg = error_of(base(run={"dt": 5e-3}))
    assert "run.dt = 0.005 does not resolve the grain's response time" in msg
    assert "τ_p/5" in msg
    # d = 0.1 mm: τ_p ≈ 1.1 ms; dt = 0.5 ms = 0.048 d/u* passes rule (2) but not rule (1)
    fine = base(particle={"diameter": 1e-4}, run={"dt": 5e-4})
    assert "does not resolve the grain's response time" in error_of(fine)
    # a finer grain with no time step in the case: the error says the default was refused,
    # and what to give instead
    msg = error_of(base(particle={"diameter": 5e-5}))
    assert "run.dt_particle (not in the case: the default, 0.02 d/u*) does not resolve" in msg
    assert "give run.dt_particle <= 0.008928" in msg
    # the step in particle units must stay ≤ 0.05 d/u*
    msg = error_of(base(run={"dt_particle": 0.08}))
    assert "run.dt_particle = 0.08 is too coarse" in msg and "0.05 d/u*" in msg
    assert load_case(base(run={"dt_particle": 0.05})).dt_particle == 0.05


def test_duration_shorter_than_a_step():
    msg = error_of(base(run={"duration": 1e-5}))
    assert "run.duration = 1e-05 s is shorter than one time step" in msg


def test_bed_coefficient_conflicts():
    msg = error_of(base(bed={"coefficients": "tsuji-1987", "restitution": 0.5}))
    assert 'bed.restitution conflicts with bed.coefficients = "tsuji-1987"' in msg
    msg = error_of(base(bed={"restitution": 0.5}))
    assert "bed.friction is required" in msg and "user" in msg
    msg = error_of(base(bed={"coefficients": "nino-garcia-1994"}, flow={"tau_ratio": 3.5}))
    assert 'bed.coefficients = "nino-garcia-1994"' in msg and "outside [0, 1]" in msg


def test_soft_contact_rules():
    msg = error_of(base(collisions={"model": "soft", "stiffness": 1.0}))
    assert "collisions.stiffness = 1.0 N/m is out of range: must be >=" in msg
    msg = error_of(base(collisions={"model": "soft", "restitution": 0.0}))
    assert "collisions.restitution = 0.0 is out of range" in msg
    # a stiff spring is fine, and hard/off accept e = 0
    assert load_case(base(collisions={"model": "hard", "restitution": 0.0}))


def test_concentration_limits_from_number_and_domain():
    msg = error_of(base(run={"n_particles": 200_000, "domain": PAPER_BOX}))
    assert "run.n_particles = 200000" in msg and "must be <= 0.05" in msg
    msg = error_of(base(run={"concentration": 1e-9, "domain": PAPER_BOX}))
    assert "run.concentration = 1e-09 puts fewer than one grain" in msg
    msg = error_of(base(run={"domain": [0.001, 0.1, 0.1]}))
    assert "run.domain" in msg and "too small" in msg


def test_output_interval_below_time_step():
    msg = error_of(base(output={"tracks_interval": 1e-6}))
    assert "output.tracks_interval = 1e-06 s is out of range: must be >= the time step" in msg


def test_bad_overrides():
    assert "must read table.key=value" in error_of(base(), ["seed"])
    assert "must name table.key" in error_of(base(), {"seed": 3})
    assert "flow.tau_ratio = -2.0 is out of range" in error_of(base(), ["flow.tau_ratio=-2"])


def test_file_errors_name_the_file(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text('[particle]\ndiameter = 1e-3\n[flow]\nsource = "loglaw"\ntau_ratio = 2\n'
                    '[run]\nduration = 1.0\nn_particles = -3\n')
    msg = error_of(path)
    assert str(path) in msg and "run.n_particles = -3 is out of range" in msg
    path.write_text("[particle\n")
    assert "not valid TOML" in error_of(path)
    assert "not found" in error_of(tmp_path / "missing.toml")


def test_case_error_is_value_error_with_key():
    with pytest.raises(ValueError) as info:
        load_case(base(particle={"diameter": -1.0}))
    assert (info.value.table, info.value.key) == ("particle", "diameter")


def test_direct_construction_validates():
    case = load_case(base())
    with pytest.raises(CaseError, match=r"run\.n_particles = 0"):
        dataclasses.replace(case, run=dataclasses.replace(case.run, n_particles=0))
    assert isinstance(dataclasses.replace(case), Case)


def test_override_errors_blame_the_override_not_the_file(tmp_path):
    """issue 16 item 6: a bad override value is named as an override (with the value given),
    with CaseError.override set for the command line to name its --set option."""
    path = tmp_path / "case.toml"
    path.write_text('[particle]\ndiameter = 0.69e-3\n[flow]\nsource = "loglaw"\ntau_ratio = 1.79\n'
                    '[run]\nduration = 1.0\nn_particles = 3\n')
    with pytest.raises(CaseError) as info:
        load_case(path, {"run.dt_particle": "abc"})
    err = info.value
    assert str(err).startswith("override run.dt_particle = 'abc': run.dt_particle must be a number")
    assert str(path) not in str(err)
    assert (err.override, err.table, err.key) == ("run.dt_particle", "run", "dt_particle")
    assert err.reason == "run.dt_particle must be a number, got 'abc' (str)"
    with pytest.raises(CaseError) as info:
        load_case(path, ["bed.model=wrong"])
    assert info.value.override == "bed.model" and '"virtual", "packed"' in str(info.value)
    with pytest.raises(CaseError) as info:
        load_case(path, {"bedd.model": "virtual"})
    assert info.value.override == "bedd.model" and "did you mean [bed]" in str(info.value)
    # the file's own value is still blamed on the file, even with overrides in effect
    path.write_text(path.read_text().replace("n_particles = 3", "n_particles = -3"))
    with pytest.raises(CaseError) as info:
        load_case(path, {"run.seed": 2})
    err = info.value
    assert err.override is None and str(err).startswith(f"{path} with override(s) run.seed = 2: run.n_particles = -3")
