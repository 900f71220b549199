"""Command line: ``saltation run | sweep | analyze | validate | flow …`` (SPEC §9)."""
from __future__ import annotations

import argparse
import json
import shlex
import sys
from pathlib import Path


class UsageError(ValueError):
    """Bad command-line input found by the CLI itself (printed as "saltation: error: …", exit 2)."""


def _out_dir(path, option="--out") -> Path:
    """An --out folder checked before any long work (saltation.io.run_directory)."""
    from .io.run_directory import check_output_directory

    return check_output_directory(path, option)


def _flow_info(args) -> int:
    from flowfields import open_dataset

    from .physics.fluid import BED_TOLERANCE

    ds = open_dataset(args.dataset)
    info = ds.describe()
    if args.json:
        print(json.dumps(info, indent=1))
        return 0
    g, b, s = info["grid"], info["box_plus"], info["spacing_plus"]
    print(f"dataset        {info['path']}")
    print(f"kind           {info['kind']}")
    bed = info.get("bed")
    if bed:
        print(f"Re_tau         {info['re_tau']:.1f}  (u* from the momentum balance at the bed top; depth above it)")
        print(f"bed            rough: porous grain layer, bed grain d+ = {bed['d_plus']:.2f} (runs need Re* = u* d/nu "
              f"within {100 * BED_TOLERANCE:.0f} %), stored down to y+ = {bed['floor_plus']:.1f} (bed top y+ = 0)")
        for key, label in (("delta_u_plus", "dU+"), ("virtual_origin_d", "virtual origin (d)"), ("ks_d_colebrook", "k_s (d)")):
            if key in bed:
                print(f"               {label} = {bed[key]:.3f}")
    else:
        print(f"Re_tau         {info['re_tau']:.1f}  (from the LES's own wall shear)")
        print("bed            smooth wall")
    print(f"grid           {g['nx']} x {g['ny']} x {g['nz']}  (x, y, z)")
    print(f"box (wall u.)  Lx+ = {b['Lx']:.1f}, y_top+ = {b['y_top']:.1f}, Lz+ = {b['Lz']:.1f}")
    hb = info["box_h"]
    print(f"box (h)        Lx = {hb['Lx']:.3f} h, y_top = {hb['y_top']:.3f} h, Lz = {hb['Lz']:.3f} h")
    print(f"spacing        dx+ = {s['dx']:.2f}, dz+ = {s['dz']:.2f}, first centre y+ = {s['y_first_centre']:.3f}, max dy+ = {s['dy_max']:.2f}")
    iv = info["snapshot_interval_plus"]
    print(f"snapshots      {info['snapshots']} over t+ = {info['time_span_plus']:.1f}" + (f", interval dt+ = {iv:.3f}" if iv else ""))
    print(f"storage        {info['storage']['dtype']}")
    prov = info["provenance"]
    solver = prov.get("solver")
    rows = [
        ("OpenFOAM", prov.get("openfoam_version")),
        ("solver", f"{solver.get('application')}; {solver.get('les_model')}" if isinstance(solver, dict) else solver),
        ("made by", prov.get("les_command_line") or prov.get("command")),
        ("imported by", prov.get("import_command")),
    ]
    for label, value in rows:
        if value:
            print(f"{label:<15}{value}")
    return 0


def _flow_check(args) -> int:
    from flowfields import open_dataset
    from flowfields.check import write_profile_check

    out = _out_dir(args.out)
    ds = open_dataset(args.dataset)
    summary = write_profile_check(ds, out)
    print(f"Re_tau = {summary['re_tau']:.1f}; first cell centre at y+ = {summary['first_cell_y_plus']:.3f}")
    print(f"{'y+':>6} {'u+ (LES)':>9} {'u+ (law)':>9} {'diff':>7}  law")
    for r in summary["law_of_the_wall"]:
        print(f"{r['y_plus']:6.0f} {r['u_plus_les']:9.3f} {r['u_plus_law']:9.3f} {100 * r['rel_diff']:6.1f}%  {r['law']}")
    if "log_region" in summary:
        lo, hi = summary["log_region"]
        print(f"log region y+ {lo:.0f}-{hi:.0f}: max |u+/law - 1| = {100 * summary['log_region_max_abs_rel_diff']:.1f}%")
    rb = summary.get("rough_bed")
    if rb and "fit_error" in rb:
        print(f"rough bed: grain d+ = {rb['d_plus']:.2f}; no roughness fit: {rb['fit_error']}")
    elif rb:
        print(f"rough bed: grain d+ = {rb['d_plus']:.2f}; u* from {rb['u_tau_source']}")
        print(f"fitted log law u+ = 2.44 ln(y+ + y_d+) + 5.5 - dU+ over y+ = {rb['log_range_plus'][0]:.0f}-"
              f"{rb['log_range_plus'][1]:.0f} (from the bed top):")
        print(f"  dU+ = {rb['delta_u_plus']:.2f}, virtual origin y_d = {rb['virtual_origin_d']:.3f} d below the bed top, "
              f"max deviation {100 * rb['log_fit_max_rel_dev']:.1f}%")
        print(f"  equivalent k_s = {rb['ks_d_colebrook']:.2f} d (Colebrook), {rb['ks_d_nikuradse']:.2f} d (Nikuradse fully rough)")
        print("  Colebrook dU+ at k_s = 1 / 2 / 2.5 d: " + " / ".join(f"{v:.2f}" for v in rb["colebrook_delta_u_plus"].values())
              + "   (measured minus these: " + " / ".join(f"{v:+.2f}" for v in rb["delta_u_minus_colebrook_at_ks_d"].values()) + ")")
        print(f"{'y/d':>6} {'y+':>7} {'u+ (LES)':>9} {'u+ (fit)':>9} {'diff':>7} {'smooth log law':>15}")
        for r in rb["table"]:
            print(f"{r['y_d']:6.2f} {r['y_plus']:7.1f} {r['u_plus_les']:9.3f} {r['u_plus_fitted_law']:9.3f} "
                  f"{100 * r['rel_diff']:6.1f}% {r['u_plus_smooth_log_law']:15.3f}" + ("" if r["in_fit_range"] else "  (outside fit range)"))
        print(f"u+ at the bed top = {rb['u_at_bed_top']:.3f}")
    print(f"streamwise r.m.s. peak u'+ = {summary['u_rms_peak']:.2f} at y+ = {summary['u_rms_peak_y_plus']:.1f}"
          + (f" ({rb['u_rms_peak_y_d']:.2f} d above the bed top)" if rb else ""))
    print(f"wrote {out / 'profile.csv'}, {out / 'law_of_the_wall.csv'}, {out / 'profile_check.json'}, {out / 'profile.png'}")
    return 0


def _flow_import(args) -> int:
    from flowfields.importer import import_series

    _out_dir(args.out)
    prov = {}
    if args.provenance:
        src = Path(args.provenance)
        if not src.is_file():
            raise UsageError(f"--provenance {args.provenance!r}: no such file")
        try:
            prov = json.loads(src.read_text(encoding="utf-8"))
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise UsageError(f"--provenance {args.provenance!r}: not valid JSON ({exc})") from None
        if not isinstance(prov, dict):
            raise UsageError(f"--provenance {args.provenance!r}: must hold a JSON object (the generator's "
                             f"provenance.json), got {type(prov).__name__}")
        prov["les_command_line"] = prov.pop("command_line", None)
    prov["import_command"] = "saltation " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    path = import_series(args.src, args.out, nu=args.nu, provenance=prov, y_max_plus=args.y_max_plus, dtype=args.dtype,
                         max_snapshots=args.max_snapshots)
    print(f"wrote dataset {path}")
    return 0


def _flow_generate(args) -> int:
    from flowfields.generate import ChannelParams, generate

    _out_dir(args.out)
    _out_dir(args.work_dir, "--work-dir")
    try:
        params = _channel_params(args, ChannelParams)
    except ValueError as exc:  # a parameter out of range: named, before any OpenFOAM work
        raise UsageError(f"flow generate: {exc}") from None
    cmd = "saltation " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    path = generate(params, args.out, work_dir=args.work_dir, command_line=cmd, y_max_plus=args.y_max_plus, dtype=args.dtype)
    print(f"wrote dataset {path}")
    return 0


def _channel_params(args, ChannelParams):
    return ChannelParams(
        re_tau=args.re_tau,
        lx_h=args.lx,
        lz_h=args.lz,
        nx=args.nx,
        ny=args.ny,
        nz=args.nz,
        first_cell_yplus=args.first_cell_yplus,
        snapshot_interval_tplus=args.interval,
        n_snapshots=args.snapshots,
        spinup_tplus=args.spinup,
        nprocs=args.np,
        initial=args.initial,
        bed=args.bed,
        bed_d_plus=args.bed_d_plus,
        bed_depth_d=args.bed_depth,
        bed_porosity=args.bed_porosity,
        ny_bed=args.ny_bed,
    )


def _set_options(items) -> tuple[dict, dict]:
    """--set items → ({"table.key": typed value}, {"table.key": the item as typed})."""
    over, given = {}, {}
    for item in items or []:
        if "=" not in item:
            raise UsageError(f"--set {item!r}: expects TABLE.KEY=VALUE (e.g. --set run.seed=3)")
        k, v = item.split("=", 1)
        over[k.strip()] = v.strip()
        given[k.strip()] = item
    return _typed(over), given


def _blame_set(err, given: dict) -> str:
    """A CaseError's text, blamed on the --set option that gave the value where it did."""
    name = getattr(err, "override", None)
    reason = getattr(err, "reason", None) or str(err)
    if name is None and err.table and err.key:  # raised after loading (domain rules, run checks)
        name = next((n for n in given if n.replace("__", ".") == f"{err.table}.{err.key}"), None)
    if name is None:
        return str(err)
    if name in given:
        return f"--set {given[name]}: {reason}"
    return f"--set: {reason}"


def _run(args) -> int:
    from .case.schema import CaseError, load_case
    from .engine.simulation import RunInterrupted, run

    overrides, given = _set_options(args.set)
    try:  # the case and the output folder first: bad input is an error before any long work
        case = load_case(args.case, overrides or None)
        out = args.out or case.output.directory or Path("runs") / (case.run.name or "run")
        args._out_dir = Path(out)
        _out_dir(out, "--out" if args.out else "run directory")
        res = run(args.case, out=out, progress=not args.quiet, resume=args.resume, overwrite=args.overwrite,
                  **overrides)
    except CaseError as err:
        raise UsageError(_blame_set(err, given)) from None
    except RunInterrupted as stop:
        s = stop.result.summary
        print(f"saltation: interrupted (signal {stop.signum}) at step {s['steps']}; outputs flushed, "
              f"checkpoint and summary.json in {stop.result.directory}", file=sys.stderr)
        print(f"saltation: continue with: saltation run {shlex.quote(args.case)} --resume --out "
              f"{shlex.quote(str(stop.result.directory))}" + "".join(f" --set {shlex.quote(x)}" for x in args.set or []),
              file=sys.stderr)
        return 128 + stop.signum
    s = res.summary
    j = s["jumps"]
    print(f"run directory  {res.directory}")
    print(f"grains         {s['n_particles']}  (C = {100 * s['concentration']:.3g} %)  tau*/tau*c = {s['tau_ratio']:.3g}  tau* = {s['tau_star']:.4g}  Re* = {s['re_star']:.2f}")
    print(f"simulated      {s['simulated_time_s']:.3g} s = {s['simulated_time_particle']:.1f} d/u*  ({s['steps']} steps)")
    if j["count"]:
        print(f"jumps          {j['count']} counted (first {j['discarded_first_per_particle']} per grain dropped)")
        print(f"  H/d = {j['H_mean']:.2f} ± {j['H_std']:.2f}   L/d = {j['L_mean']:.2f} ± {j['L_std']:.2f}   U/u* = {j['U_mean']:.2f} ± {j['U_std']:.2f}")
    else:
        print(f"jumps          none counted yet ({j['recorded']} recorded; each grain's first {j['discarded_first_per_particle']} are dropped)")
    t = s["timing"]
    print(f"timing         wall {t['wall_s']:.1f} s (compile {t['compile_s']:.1f} s), {s['particle_steps_per_s']:.3g} particle-steps/s on {t['threads']} thread(s)")
    return 0


def _typed(over: dict) -> dict:
    """--set values are TOML values (numbers, booleans, strings; bare words are strings)."""
    import tomllib

    out = {}
    for k, v in over.items():
        try:
            out[k] = tomllib.loads(f"v = {v}")["v"]
        except tomllib.TOMLDecodeError:
            out[k] = v
    return out


class _QuietDaskAfterCtrlC:
    """While a sweep runs: SIGINT raises KeyboardInterrupt as usual, and from then on Dask's
    shutdown chatter (workers cancelled, killed, a cluster closed half-started) is dropped,
    so that Ctrl-C ends with the one "sweep interrupted" line."""

    def __init__(self):
        self.interrupted = False
        self._old = None

    def filter(self, record) -> bool:  # logging.Filter protocol
        return not (self.interrupted and record.name.startswith(("distributed", "tornado", "asyncio")))

    def _on_sigint(self, signum, frame):
        self._quiet()
        raise KeyboardInterrupt

    def _quiet(self):
        import logging

        self.interrupted = True
        for name in ("", "distributed"):  # distributed adds its handler when it is first imported
            for h in logging.getLogger(name).handlers:
                if self not in h.filters:
                    h.addFilter(self)

    def __enter__(self):
        import signal
        import threading

        if threading.current_thread() is threading.main_thread() and signal.getsignal(signal.SIGINT) is signal.default_int_handler:
            self._old = signal.signal(signal.SIGINT, self._on_sigint)
        return self

    def __exit__(self, exc_type, exc, tb):
        import logging
        import signal

        if isinstance(exc, KeyboardInterrupt):  # distributed's own handler stays filtered: the
            self._quiet()                       # cluster's exit-time close still logs
            self._quiet_atexit()
        for h in logging.getLogger().handlers:  # the application's handlers are left as found
            h.removeFilter(self)
        if self._old is not None:
            signal.signal(signal.SIGINT, self._old)
        return False

    def _quiet_atexit(self):
        """A LocalCluster interrupted while starting is closed by distributed at exit,
        which fails on its half-started workers (a traceback): close it quietly instead."""
        import atexit
        import contextlib

        spec = sys.modules.get("distributed.deploy.spec")
        close = getattr(spec, "close_clusters", None)
        if close is None:
            return
        atexit.unregister(close)

        def quiet_close():
            with contextlib.suppress(BaseException):
                close()

        atexit.register(quiet_close)


def _check_scheduler_address(address: str) -> None:
    """--scheduler must read [SCHEME://]HOST:PORT with a scheme Dask knows."""
    from .studies.sweep import import_dask

    import_dask()
    from distributed.comm.addressing import parse_address
    from distributed.comm.registry import get_backend

    try:
        scheme, _ = parse_address(address)
        backend = get_backend(scheme)
        if scheme != "inproc":
            backend.get_address_host_port(parse_address(address)[1])
    except (ValueError, NotImplementedError) as exc:
        raise UsageError(f"--scheduler {address!r}: {exc}; give the scheduler's address, e.g. tcp://HOST:8786") from None


def _sweep(args) -> int:
    from .studies.sweep import format_table, load_sweep, run_sweep

    sweep = load_sweep(args.sweep)
    out = Path(args.out or Path("sweeps") / (sweep.path.stem if sweep.path else "sweep"))
    args._out_dir = out
    _out_dir(out, "--out" if args.out else "sweep folder")
    for option in ("workers", "threads_per_worker"):
        n = getattr(args, option)
        if n is not None and n < 1:
            raise UsageError(f"--{option.replace('_', '-')} {n}: must be at least 1")
    if args.scheduler:
        _check_scheduler_address(args.scheduler)
    try:
        with _QuietDaskAfterCtrlC():
            df = run_sweep(sweep, out=out, scheduler=args.scheduler, workers=args.workers,
                           threads_per_worker=args.threads_per_worker)
    except OSError as exc:
        if not args.scheduler:
            raise
        raise UsageError(f"--scheduler {args.scheduler}: cannot reach the Dask scheduler ({exc})") from None
    print(format_table(df))
    bad = df[df["status"] != "completed"]
    if len(bad):
        print(f"saltation: {len(bad)} case(s) not completed: {', '.join(bad['case'])}", file=sys.stderr)
        return 1
    return 0


def _analyze(args) -> int:
    from .analysis.report import analyze, windows_text

    res = analyze(args.directory, out=args.out, validation=args.validation, diameter=args.diameter,
                  time_scale=args.time_scale, n_origins=args.origins)
    if res["kind"] in ("run", "tracks"):
        d = res["diffusion"]
        if d is not None:
            print(f"diffusion ({d['source']}, {d['n_particles']} grains, samples every {d['sample_interval']:.3g} d/u*)")
            print(windows_text(d))
        if d is not None and len(d.table):
            print(f"{'range':<13}{'dir':<4}{'t (d/u*)':>15} {'gamma':>6} {'95 % CI':>14} {'points':>6}")
            for _, r in d.table.iterrows():
                print(f"{r['range']:<13}{r['direction']:<4}{r['t_min']:>7.3g}-{r['t_max']:<7.3g} {r['gamma']:6.3f} "
                      f"[{r['ci_low']:.3f}, {r['ci_high']:.3f}] {r['n_points']:6d}")
        for k, v in res["problems"].items():
            print(f"not fitted: {k}: {v}")
    else:
        gv = res["tables"]["gamma_vs_paper"]
        print(f"{'table':<6}{'range':<13}{'dir':<4}{'tau':>5} {'C %':>6} {'ours':>6} {'paper':>6} {'diff':>6}")
        for _, r in gv.iterrows():
            f = lambda v: "   —  " if v is None or v != v else f"{v:6.2f}"  # noqa: E731
            print(f"{r['table']:<6}{r['range']:<13}{r['direction']:<4}{r['tau_ratio']:5.2f} {r['concentration_pct']:6.3g} "
                  f"{f(r['gamma_ours'])} {f(r['gamma_paper'])} {f(r['difference'])}  {r['note'][:70]}")
    print(f"wrote {res['out']} (CSV tables, PNG figures) and the report {res['report']}")
    return 0


def _validate(args) -> int:
    from .studies.validate import read_experiments, run_validation

    if args.data:  # before the runs: a wrong file is an error now, not after them
        try:
            read_experiments(args.data)
        except FileNotFoundError:
            raise UsageError(f"--data {args.data!r}: no such file") from None
        except (ValueError, UnicodeDecodeError) as exc:
            text = str(exc)
            raise UsageError(f"--data {text}" if text.startswith(str(args.data)) else f"--data {args.data!r}: {text}") from None
    if not args.duration_scale > 0:
        raise UsageError(f"--duration-scale {args.duration_scale}: must be a positive number")
    _out_dir(args.out)
    flows = tuple(args.flow) if args.flow else None
    if flows:
        from .studies.validate import FLOWS

        bad = [f for f in flows if f not in FLOWS]
        if bad:
            raise UsageError(f"--flow {bad[0]!r}: choose from {', '.join(repr(f) for f in FLOWS)}")
    res = run_validation(args.out, data=args.data, duration_scale=args.duration_scale, ablation=not args.no_ablation,
                         sensitivity=not args.no_sensitivity, **({"flows": flows} if flows else {}))
    print_validation(res)
    print(f"wrote {args.out}/validation.csv, references.csv, validation.png"
          + (", sensitivity.csv" if "sensitivity" in res else "") + (", ablation.csv" if "ablation" in res else ""))
    return 0


def _floats(text, option, count=None):
    try:
        vals = [float(x) for x in str(text).split(",") if x.strip()]
    except ValueError:
        raise UsageError(f"{option} {text!r}: must be numbers separated by commas") from None
    if not vals or any(not v > 0 for v in vals) or (count and len(vals) != count):
        raise UsageError(f"{option} {text!r}: must be {count or 'one or more'} positive numbers separated by commas")
    return vals


def _threshold(args) -> int:
    from .case.schema import load_case
    from .studies.threshold import threshold_study

    overrides, given = _set_options(args.set)
    load_case(args.case, overrides or None)  # a bad case or --set fails now, before any run
    out = Path(args.out or Path("thresholds") / Path(args.case).stem)
    _out_dir(out, "--out")
    kw = {}
    if args.tau_stars:
        kw["tau_stars"] = _floats(args.tau_stars, "--tau-stars")
    if args.ratios:
        kw["ratios"] = _floats(args.ratios, "--ratios")
    if args.width:
        kw["width_d"] = _floats(args.width, "--width", 2)
    for option in ("duration", "coverage"):
        v = getattr(args, option)
        if v is not None and not v > 0:
            raise UsageError(f"--{option} {v}: must be a positive number")
    if args.coverage is not None:
        kw["coverage"] = args.coverage
    if args.duration is not None:
        kw["duration_d"] = args.duration
    if args.settle is not None:
        if not args.settle >= 0:
            raise UsageError(f"--settle {args.settle}: must be a number >= 0")
        kw["settle_d"] = args.settle
    res = threshold_study(args.case, out, overrides=overrides, progress=not args.quiet, **kw)
    print(f"\nd = {1e3 * res['diameter_m']:.3g} mm, D* = {res['d_star']:.3g}; Shields (Soulsby & Whitehouse 1997) "
          f"theta_cr = {res['shields_soulsby_whitehouse_1997']:.4f}")
    print(f"{'tau*':>8} {'q*':>10} {'moving %':>9} {'MPM':>9} {'W&P':>9} {'FLvB':>9} {'A-W':>9}")
    for r in res["table"]:
        print(f"{r['tau_star']:8.4f} {r['q_star']:10.3g} {100 * r['fraction_moving']:9.3f} "
              f"{r['Meyer-Peter & Müller 1948']:9.3g} {r['Wong & Parker 2006']:9.3g} "
              f"{r['Fernandez Luque & van Beek 1976']:9.3g} {r.get('Ackers-White', float('nan')):9.3g}")
    if res["tau_star_c"] is not None:
        print(f"tau*_c (q* = 1e-4) = {res['tau_star_c']:.4f}  = {res['tau_star_c_over_shields']:.3f} x Shields")
    else:
        print(f"tau*_c not found: {res['tau_star_c_reason']}")
    print(f"wrote {out}/threshold.json, threshold.csv, threshold.png")
    return 0


def print_validation(res: dict) -> None:
    """The validation table: model mean ± std against each regression (ratio model/regression)."""
    import pandas as pd

    rows = res["validation"]
    refs = pd.DataFrame(res["references"])
    print("published regressions (H/d, L/d, U/u*; where each was read: docs/references.md):")
    for ratio, g in refs.groupby("tau_ratio"):
        cells = [f"{r['regression']}: " + ", ".join(f"{q} {r[q]:.2f}" for q in ("H", "L", "U") if r[q] == r[q])
                 for _, r in g.iterrows()]
        print(f"  tau*/tau*c = {ratio}: " + "; ".join(c for c in cells if ":" in c and c.split(": ")[1]))
    for q, unit in (("H", "d"), ("L", "d"), ("U", "u*")):
        print(f"\n{q} ({unit}): model mean ± std [jumps], ratio to each regression, envelope ±25 % test")
        for r in rows:
            ratios = "  ".join(f"/{k.split(' / ')[1]} {v:.2f}" for k, v in r.items()
                               if k.startswith(f"{q} / ") and v == v)
            env = r.get(f"{q}_in_envelope")
            env_s = "" if env is None else (" IN " if env else " OUT") + f" [{r[f'{q}_env_lo']:.2f}, {r[f'{q}_env_hi']:.2f}]"
            print(f"  {r['flow']:>13} {r['tau_ratio']:4.2f}: {r[f'{q}_mean']:6.2f} ± {r[f'{q}_std']:<5.2f} [{r['count']}]"
                  f"{env_s}  {ratios}")
    for flow, why in res.get("skipped", {}).items():
        print(f"\n{flow}: skipped — {why}")
    grows = {r["flow"]: r["grows_with_stage"] for r in rows}
    print("\nH, L and U all grow with tau*/tau*c: " + ", ".join(f"{k} {'yes' if v else 'NO'}" for k, v in grows.items()))
    for key, title in (("sensitivity", "sensitivity"), ("ablation", "force ablation")):
        if key in res:
            print(f"\n{title} at tau*/tau*c = {res[key][0].get('tau_ratio', 1.79)} (change vs the first row):")
            for r in res[key]:
                print(f"  {r['variant']:<60} H {r['H_mean']:5.2f} ({r['H_change_pct']:+6.1f} %)  L {r['L_mean']:6.2f} "
                      f"({r['L_change_pct']:+6.1f} %)  U {r['U_mean']:5.2f} ({r['U_change_pct']:+6.1f} %)  [{r['count']}]")


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="saltation", description="Saltating sand grains in stored LES channel flow.")
    sub = p.add_subparsers(dest="command", required=True)

    r = sub.add_parser("run", help="one simulation; writes a run directory")
    r.add_argument("case", help="case file (TOML)")
    r.add_argument("--out", default=None, help="run directory (default: output.directory or runs/NAME)")
    r.add_argument("--set", action="append", metavar="TABLE.KEY=VALUE", help="override a case-file key (repeatable)")
    r.add_argument("--quiet", action="store_true", help="no progress bar")
    r.add_argument("--resume", action="store_true",
                   help="continue from the run directory's checkpoint (written periodically and on SIGINT/SIGTERM)")
    r.add_argument("--overwrite", action="store_true",
                   help="replace the outputs of an earlier run in the run directory (other files are left alone)")
    r.set_defaults(func=_run)

    sw = sub.add_parser("sweep", help="many cases (a [sweep] grid) on a local or remote Dask cluster; skips finished cases")
    sw.add_argument("sweep", help="sweep file (TOML): a base case and a [sweep] table of lists")
    sw.add_argument("--out", default=None, help="sweep folder (default: sweeps/<file stem>)")
    sw.add_argument("--scheduler", default=None, metavar="ADDRESS",
                    help="an existing Dask scheduler, tcp://HOST:PORT (default: a LocalCluster on 127.0.0.1)")
    sw.add_argument("--workers", type=int, default=None, help="cases at a time (default: cores / threads per worker)")
    sw.add_argument("--threads-per-worker", type=int, default=None,
                    help="Numba threads per case (default: cores / workers)")
    sw.set_defaults(func=_sweep)

    a = sub.add_parser("analyze", help="jump statistics, diffusion exponents, collision statistics, figures, HTML report")
    a.add_argument("directory", metavar="PATH",
                   help="a run directory, a sweep directory (cases/NAME/), or a tracks file (.csv/.parquet, columns "
                        "particle, t in d/u*, x and z unwrapped in d; y optional): diffusion only")
    a.add_argument("--out", default=None, help="output folder (default PATH/analysis; for a file <stem>_analysis/ beside it)")
    a.add_argument("--diameter", type=float, default=1.0,
                   help="tracks file only: the grain diameter d in the file's length unit (x, y, z are divided by it; "
                        "default 1: already in d)")
    a.add_argument("--time-scale", type=float, default=1.0,
                   help="tracks file only: d/u* in the file's time unit (t is divided by it; default 1: already in d/u*)")
    a.add_argument("--origins", type=int, default=8,
                   help="tracks file only: time origins of the displacement statistics (default 8, spread over the "
                        "record; 1: a tracer release at the first origin, 10 %% into the record)")
    a.add_argument("--validation", default=None,
                   help="folder written by `saltation validate nino-garcia` (default: DIR/validation or DIR/../validation if present)")
    a.set_defaults(func=_analyze)

    v = sub.add_parser("validate", help="single-grain validation cases and their comparison table/figure")
    v.add_argument("which", choices=("nino-garcia",))
    v.add_argument("--data", default=None, help="experimental CSV (columns: source, tau_ratio, H_mean, H_std, L_mean, L_std, U_mean, U_std)")
    v.add_argument("--out", default="validation", help="output folder (default ./validation)")
    v.add_argument("--duration-scale", type=float, default=1.0, help="scale the cases' durations (quick looks)")
    v.add_argument("--no-ablation", action="store_true", help="skip the force-ablation runs")
    v.add_argument("--flow", action="append", default=None,
                   help='flow(s) to run: "rough LES" (default first), "smooth LES", "rough log law"; repeat the option; default all three')
    v.add_argument("--no-sensitivity", action="store_true", help="skip the sensitivity table")
    v.set_defaults(func=_validate)

    th = sub.add_parser("threshold", help="incipient motion: resting grains on the packed bed at a series of tau*; "
                                          "tau*_c where q* = 1e-4, transport rates against bed-load formulas")
    th.add_argument("case", help="case file (TOML): grain, fluid, flow; bed.model = \"packed\", collisions.model = \"soft\"")
    th.add_argument("--out", default=None, help="study folder (default thresholds/<case stem>); finished runs are reused")
    th.add_argument("--set", action="append", metavar="TABLE.KEY=VALUE", help="override a case-file key (repeatable)")
    th.add_argument("--tau-stars", default=None, help="Shields numbers to run, comma-separated (default: --ratios)")
    th.add_argument("--ratios", default=None,
                    help="tau* as multiples of the Shields curve's theta_cr (default 0.4,0.55,0.7,0.85,1,1.2,1.5)")
    th.add_argument("--width", default=None, help="bed Lx,Lz in d (default 20,12)")
    th.add_argument("--coverage", type=float, default=None, help="grains at rest per bed sphere (default 0.4; random filling holds ~0.45)")
    th.add_argument("--duration", type=float, default=None, help="simulated time per tau*, in d/u* (default 200)")
    th.add_argument("--settle", type=float, default=None,
                    help="d/u* run before the measured duration (default 0 for spheres, which start in "
                         "equilibrium; 10 for bonded-sphere grains, which are lowered onto the bed and settle)")
    th.add_argument("--quiet", action="store_true", help="no progress bars")
    th.set_defaults(func=_threshold)

    flow = sub.add_parser("flow", help="make, ingest and describe LES datasets")
    fsub = flow.add_subparsers(dest="flow_command", required=True)

    fi = fsub.add_parser("info", help="grid, Re_tau, time span, snapshot interval of a dataset")
    fi.add_argument("dataset", nargs="?", default=None, help="dataset folder (default: the shipped one)")
    fi.add_argument("--json", action="store_true", help="print JSON")
    fi.set_defaults(func=_flow_info)

    fc = fsub.add_parser("check", help="mean and r.m.s. profiles against the law of the wall (table + figure)")
    fc.add_argument("dataset", nargs="?", default=None, help="dataset folder (default: the shipped one)")
    fc.add_argument("--out", default="flow_check", help="output folder (default: ./flow_check)")
    fc.set_defaults(func=_flow_check)

    fm = fsub.add_parser("import", help="import a foamToVTK / meshio series into a dataset")
    fm.add_argument("src", help=".vtm.series / .vtu.series / .xdmf file, a VTK folder, or one mesh file")
    fm.add_argument("--out", required=True, help="dataset folder to write")
    fm.add_argument("--nu", type=float, required=True, help="kinematic viscosity of the LES (m²/s)")
    fm.add_argument("--y-max-plus", type=float, default=None, help="keep y+ up to this (default: lower half)")
    fm.add_argument("--dtype", choices=("float32", "int16"), default="float32")
    fm.add_argument("--max-snapshots", type=int, default=None, help="keep only the first N snapshots")
    fm.add_argument("--provenance", default=None,
                    help="JSON file with the LES's provenance (the generator writes provenance.json) to store with the data")
    fm.set_defaults(func=_flow_import)

    fg = fsub.add_parser("generate", help="run the project's OpenFOAM LES-WALE channel and import its snapshots")
    fg.add_argument("--out", required=True, help="dataset folder to write")
    fg.add_argument("--work-dir", default="les_work", help="where the OpenFOAM case runs (default ./les_work)")
    fg.add_argument("--re-tau", type=float, default=395.0)
    fg.add_argument("--lx", type=float, default=4.0, help="Lx/h")
    fg.add_argument("--lz", type=float, default=2.0, help="Lz/h")
    fg.add_argument("--nx", type=int, default=48)
    fg.add_argument("--ny", type=int, default=64)
    fg.add_argument("--nz", type=int, default=64)
    fg.add_argument("--first-cell-yplus", type=float, default=0.8)
    fg.add_argument("--interval", type=float, default=4.0, help="snapshot interval in t+")
    fg.add_argument("--snapshots", type=int, default=80)
    fg.add_argument("--spinup", type=float, default=650.0, help="discarded spin-up in t+")
    fg.add_argument("--np", type=int, default=1, help="MPI ranks (decomposePar + mpirun -np N)")
    fg.add_argument("--initial", choices=("map", "perturb"), default="map")
    fg.add_argument("--y-max-plus", type=float, default=None)
    fg.add_argument("--dtype", choices=("float32", "int16"), default="float32")
    fg.add_argument("--bed", choices=("smooth", "porous"), default="smooth",
                    help="smooth walls, or a sand bed inside the LES: a porous layer of packed grains with Ergun drag "
                         "(SPEC §3 rough bed; y = 0 of the dataset is then the bed top)")
    fg.add_argument("--bed-d-plus", type=float, default=19.5,
                    help="bed grain diameter in wall units = the grains' Re* = u* d/nu (default 19.5: Nino & Garcia's "
                         "stages span 17.5-21.4 for d = 0.69 mm)")
    fg.add_argument("--bed-depth", type=float, default=1.0, help="porous layer thickness below the bed top, in d")
    fg.add_argument("--bed-porosity", type=float, default=0.2595,
                    help="bulk porosity of the packing (0.2595 close-packed ... 0.476 simple cubic)")
    fg.add_argument("--ny-bed", type=int, default=12, help="uniform cells across the porous layer")
    fg.set_defaults(func=_flow_generate)
    return p


def _interrupted(args) -> str:
    """The line printed on Ctrl-C: what was interrupted and what to do next."""
    cmd = getattr(args, "command", None)
    out = getattr(args, "_out_dir", None)
    again = "saltation " + " ".join(shlex.quote(a) for a in getattr(args, "_argv", []))
    if cmd == "run":
        if out is None:
            return "saltation: interrupted while loading the case; nothing was written"
        from .io.run_directory import CHECKPOINT_NAME

        sets = "".join(f" --set {shlex.quote(x)}" for x in args.set or [])
        if (out / CHECKPOINT_NAME).exists():
            return (f"saltation: interrupted; the checkpoint {out / CHECKPOINT_NAME} is kept: continue with: "
                    f"saltation run {shlex.quote(args.case)} --resume --out {shlex.quote(str(out))}{sets}")
        try:  # files of this run (config.toml, ...) make a plain rerun refuse the folder
            used = out.is_dir() and any(p.name != ".lock" for p in out.iterdir())
        except OSError:
            used = False
        if used:
            argv = [a for a in getattr(args, "_argv", []) if a not in ("--resume", "--overwrite")] + ["--overwrite"]
            again = "saltation " + " ".join(shlex.quote(a) for a in argv)
        return (f"saltation: run interrupted before a checkpoint was written (while loading the flow or "
                f"compiling kernels): nothing to resume in {out}; start again with: {again}")
    if cmd == "sweep":
        where = f" in {out}" if out is not None else ""
        return f"saltation: sweep interrupted; finished cases are kept{where}: run the same command again to continue"
    what = f"flow {args.flow_command}" if cmd == "flow" else cmd or "command"
    return f"saltation: {what} interrupted; its output may be incomplete: run it again with: {again}"


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    args = argparse.Namespace()
    try:
        args = build_parser().parse_args(argv)
        args._argv = argv
        from flowfields.dataset import DatasetError
        from flowfields.openfoam import OpenFOAMError

        from .analysis.variance import AnalysisError
        from .case.schema import CaseError
        from .engine.simulation import SimulationError
        from .io.run_directory import OutputDirectoryError, RunDirectoryError
        from .studies.sweep import MissingExtraError

        try:
            return int(args.func(args) or 0)
        except (DatasetError, CaseError, SimulationError, AnalysisError, FileNotFoundError, UsageError,
                OutputDirectoryError, RunDirectoryError, MissingExtraError, OpenFOAMError) as exc:
            print(f"saltation: error: {exc}", file=sys.stderr)
            return 2
    except KeyboardInterrupt:  # Ctrl-C at any moment: one line, no traceback (the run loop's own
        # RunInterrupted, a checkpoint written, is answered by _run with the resume command)
        try:
            print(_interrupted(args), file=sys.stderr)
        except KeyboardInterrupt:
            pass
        return 130


if __name__ == "__main__":
    sys.exit(main())
