"""Where the dense steps spend their time, kernel by kernel: Linux ``perf`` samples of the
compiled code, named.

    python benchmarks/profile_perf.py [--concentration 3.94] [--tau-ratio 1.79]
        [--spinup 1.0] [--steps 200] [--frequency 4000] [--top 25] [--keep DIR]
        [--cases cases/concentration_sweep_reduced.toml] [--spinup-states DIR]
        [--annotate NAME ... [--lines 40]]

Builds the reduced sweep case at that concentration (cases/concentration_sweep_reduced.toml,
as benchmarks/bench_dense.py), spins it up (default 1 s: the dense near-bed layer forms
over ~1 s), then runs ``perf record`` on this process for the timed steps only, on one
thread. perf cannot name code that Numba compiled at run time, so the script writes the
perf map (/tmp/perf-PID.map) itself: every function of every compiled library of the
saltation package, located from the symbol table of its object code (``nm``) and the
address of its entry point. Functions LLVM inlined are counted in their caller (the
sub-step kernels of contacts/phase.py are mostly inlined into ``_run_block``, ``_forces``
and ``_wake_up``); parallel loops run in gufuncs that are named only when they have a
symbol of their own (``unnamed``: the rest). The table gives each function's share of the
samples taken in compiled code, and the share of all samples that were compiled code.
``--cases cases/concentration_sweep.toml`` profiles the paper's domain instead, and
``--spinup-states DIR`` loads a spin-up that ``bench_dense.py --spinup-states DIR`` saved
(the paper's domain takes ~1 h at 3.94 %) or saves its own there. ``--annotate NAME``
(e.g. ``contacts.phase._run_block``) adds the samples of that function instruction by
instruction: its machine code disassembled from the object code (``objdump``) with each
instruction's share of the function's samples, the hottest ``--lines`` with the code
around them (a sample is charged to the instruction after the one that stalled).

It compiles everything afresh in a temporary NUMBA_CACHE_DIR (a library loaded from the
cache has no object code to read symbols from), which takes a minute or two before the
spin-up. Needs ``perf`` (Debian: linux-perf) and ``nm`` (binutils); a VM without hardware
counters samples the CPU clock, which is what is used here.
"""
from __future__ import annotations

import argparse
import collections
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def _short(symbol: str) -> str:
    """module.function of a Numba symbol (_ZN<len><name>...: the length-prefixed names)."""
    m = re.match(r"_ZN(?:7cpython)?(.*)", symbol)
    if not m:
        return symbol
    rest, parts = m.group(1), []
    while rest and rest[0].isdigit():
        k = re.match(r"\d+", rest).group(0)
        parts.append(rest[len(k):len(k) + int(k)])
        rest = rest[len(k) + int(k):]
    name = ".".join(p for p in parts if p)
    return (name.removeprefix("saltation.") + (".wrapper" if symbol.startswith("_ZN7cpython") else "")) or symbol


def _library_symbols(lib, path: Path, owner: str) -> list[tuple[int, int, str, str, int]]:
    """(address, size, name, object file, offset in it) of every function in a compiled
    library, located from its object code's symbol table and the address of one of them;
    [] for a library loaded from the cache (no object code). A parallel loop's gufunc is
    named after ``owner``, the kernel whose library links it."""
    try:
        code = lib._get_compiled_object()  # only after a fresh compile (module docstring)
    except Exception:  # noqa: BLE001 - loaded from a cache: nothing to read
        return []
    path.write_bytes(code)
    table = subprocess.run(["nm", "-S", "--defined-only", str(path)], capture_output=True, text=True,
                           check=True).stdout
    symbols = {}
    for line in table.splitlines():
        f = line.split()
        if len(f) == 4 and f[2] in "tT":
            symbols[f[3]] = (int(f[0], 16), int(f[1], 16))
    for name, (off, _) in symbols.items():
        try:
            base = lib.get_pointer_to_function(name) - off
        except Exception:  # noqa: BLE001 - not an exported function
            continue
        if base > 0:
            return [(base + o, size, f"{owner}.parallel_loop" if "numba_parfor_gufunc" in n else _short(n),
                     str(path), o) for n, (o, size) in symbols.items()]
    return []


def write_perf_map(package, out_dir: Path) -> list[tuple[int, int, str, str, int]]:
    """/tmp/perf-<pid>.map for every compiled library of ``package``'s dispatchers; returns
    the functions named (_library_symbols). Object code is kept under ``out_dir``."""
    import importlib
    import pkgutil

    from numba.core.registry import CPUDispatcher

    entries, seen = [], set()
    for info in pkgutil.walk_packages(package.__path__, package.__name__ + "."):
        try:
            module = importlib.import_module(info.name)
        except Exception:  # noqa: BLE001 - an optional module that does not import here
            continue
        for obj in vars(module).values():
            if not isinstance(obj, CPUDispatcher):
                continue
            for cres in obj.overloads.values():
                # the kernel's own library and those linked into it (parallel loops' gufuncs)
                owner = f"{info.name.removeprefix(package.__name__ + '.')}.{obj.py_func.__name__}"
                libs = [cres.library]
                while libs:
                    lib = libs.pop()
                    libs += list(getattr(lib, "_linking_libraries", ()))
                    if id(lib) in seen:
                        continue
                    seen.add(id(lib))
                    entries += _library_symbols(lib, out_dir / f"lib{len(seen)}.o", owner)
    entries = sorted(set(entries))
    with open(f"/tmp/perf-{os.getpid()}.map", "w") as fh:
        for addr, size, name, _, _ in entries:
            fh.write(f"{addr:x} {size:x} {name}\n")
    return entries


def annotate(perf_data: Path, entries, name: str, lines: int) -> None:
    """Samples of the compiled function ``name`` instruction by instruction (module
    docstring, --annotate): the hottest ``lines`` instructions with the code around them."""
    fns = [e for e in entries if e[2] == name]
    if not fns:
        near = sorted({e[2] for e in entries if name.split(".")[-1] in e[2]})
        raise SystemExit(f"profile_perf: no compiled function {name!r}; similar: {near[:10]}")
    report = subprocess.run(["perf", "script", "-i", str(perf_data), "-F", "ip"], capture_output=True,
                            text=True).stdout
    ips = [int(line, 16) for line in report.split()]

    def samples(fn):
        return collections.Counter(ip - fn[0] + fn[4] for ip in ips if fn[0] <= ip < fn[0] + fn[1])

    # the copy with the most samples (parallel loops of one kernel share its name)
    addr, size, _, obj, off = max(fns, key=lambda fn: sum(samples(fn).values()))
    hits = samples((addr, size, name, obj, off))
    asm = subprocess.run(["objdump", "-d", "--no-show-raw-insn", f"--start-address={off}",
                          f"--stop-address={off + size}", obj], capture_output=True, text=True).stdout
    code = []
    for text in asm.splitlines():
        m = re.match(r"\s*([0-9a-f]+):\s*(.*)", text)
        if m:  # jump targets as offsets: the symbols spell out every argument's type
            code.append((int(m.group(1), 16), re.sub(r"<[^>]*?(\+0x[0-9a-f]+)?>", r"<\1>", m.group(2).strip())))
    total = sum(hits.values())
    print(f"\n{name}: {size} bytes, {len(code)} instructions, {total} samples; hottest {lines} "
          f"(share of the function's samples) with the instructions before them")
    index = {a: k for k, (a, _) in enumerate(code)}
    shown = set()
    for a, _ in hits.most_common(lines):
        if a not in index or a in shown:
            continue
        print("    ...")
        for b, text in code[max(0, index[a] - 6):index[a] + 2]:
            shown.add(b)
            mark = f"{100 * hits[b] / total:5.1f}%" if hits[b] else "      "
            print(f"  {mark} {b - off:6x}  {text}")


def shares(perf_data: Path, perf_map: str) -> tuple[dict[str, int], int]:
    """Samples per named function in compiled code, and all samples."""
    report = subprocess.run(["perf", "script", "-i", str(perf_data), "-F", "ip,sym,dso"], capture_output=True,
                            text=True).stdout
    counts, total = collections.Counter(), 0
    for line in report.splitlines():
        m = re.match(r"\s*[0-9a-f]+\s+(.*?)\s*\((.*)\)\s*$", line)  # ip sym (dso)
        if not m:
            continue
        total += 1
        sym, dso = m.groups()
        if perf_map in dso or "[JIT]" in dso:
            counts[sym if sym and sym != "[unknown]" else "unnamed"] += 1
    return counts, total


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--concentration", type=float, default=3.94, help="%% (one of the sweep's)")
    ap.add_argument("--tau-ratio", type=float, default=1.79)
    ap.add_argument("--spinup", type=float, default=1.0, help="simulated seconds before the profile")
    ap.add_argument("--steps", type=int, default=200, help="hydrodynamic steps profiled")
    ap.add_argument("--frequency", type=int, default=4000, help="perf samples per second")
    ap.add_argument("--top", type=int, default=25)
    ap.add_argument("--keep", default=None, help="keep perf.data, the map and the object code here")
    ap.add_argument("--cases", default=None, help="sweep file of the case (default the reduced sweep)")
    ap.add_argument("--spinup-states", default=None, metavar="DIR",
                    help="load the spun-up state from here (bench_dense.py --spinup-states), or save it here")
    ap.add_argument("--annotate", action="append", default=[], metavar="NAME",
                    help="samples of this compiled function by instruction (e.g. contacts.phase._forces); "
                         "may be given more than once")
    ap.add_argument("--lines", type=int, default=40, help="hottest instructions --annotate shows")
    args = ap.parse_args()
    for tool in ("perf", "nm"):
        if shutil.which(tool) is None:
            raise SystemExit(f"profile_perf: `{tool}` not found (Debian: apt-get install linux-perf binutils)")
    work = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="profile_perf_"))
    work.mkdir(parents=True, exist_ok=True)
    if "profile_perf_cache" not in os.environ.get("NUMBA_CACHE_DIR", ""):
        # a fresh cache, set before Numba is imported: re-run this script in it
        env = dict(os.environ, NUMBA_CACHE_DIR=str(work / "profile_perf_cache"), NUMBA_NUM_THREADS="1",
                   SALTATION_SERIAL_COMPILE="1")
        child = subprocess.Popen([sys.executable, __file__, *sys.argv[1:], "--keep", str(work)], env=env)
        rc = child.wait()
        perf_map = Path(f"/tmp/perf-{child.pid}.map")
        if args.keep:
            print(f"\n(perf data and object code: {work}; perf map: {perf_map})")
        else:  # nothing left behind
            shutil.rmtree(work, ignore_errors=True)
            perf_map.unlink(missing_ok=True)
        sys.exit(rc)

    import numba

    import saltation

    sys.path.insert(0, str(HERE))
    import bench_dense as bd  # noqa: E402 - the benchmarks' folder

    cases = args.cases or bd.REDUCED
    sim, ds, st, ws = bd.build(*bd._sweep_case(cases, args.concentration, args.tau_ratio), out=str(work / "unused_run"))
    steps = bd.steps
    numba.set_num_threads(1)

    t0 = time.perf_counter()
    spin = int(round(args.spinup / sim.case.dt))  # seconds per step
    spun, how = None, f"spin-up ({spin} steps)"
    if args.spinup_states:
        spun = bd.spun_state_path(args.spinup_states, cases, args.concentration, args.tau_ratio, args.spinup, 1)
        meta = bd.spun_meta(cases, args.concentration, args.tau_ratio, sim, spin, 1)
    if spun is not None and spun.exists():
        steps(sim, ds.arrays, st, ws, 0, 1)  # compile (the state is then replaced)
        st, ws, _ = bd.load_spun_into(spun, meta, sim, st, ws)
        how = f"spin-up loaded from {spun}"
    else:
        steps(sim, ds.arrays, st, ws, 0, spin)
        if spun is not None:
            bd.save_spun_state(spun, {**meta, "trace": [], "wall_s": time.perf_counter() - t0}, st, ws,
                               sim.stepper.state_arrays())
    print(f"N = {sim.n}, C = {args.concentration} %: compile and {how}: {time.perf_counter() - t0:.0f} s",
          file=sys.stderr)
    data = work / "perf.data"
    rec = subprocess.Popen(["perf", "record", "-F", str(args.frequency), "-o", str(data), "-p", str(os.getpid())],
                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    time.sleep(1.0)  # perf attaches
    t0 = time.perf_counter()
    steps(sim, ds.arrays, st, ws, spin, args.steps)
    wall = time.perf_counter() - t0
    rec.send_signal(signal.SIGINT)
    rec.wait()
    entries = write_perf_map(saltation, work)
    named = len(entries)
    counts, total = shares(data, f"perf-{os.getpid()}.map")
    jit = sum(counts.values())
    print(f"\n{args.steps} steps of {sim.n} grains at C = {args.concentration} %, one thread: {wall:.1f} s, "
          f"{sim.n * args.steps / wall:.3g} grain-steps/s; {total} samples, {100 * jit / max(total, 1):.0f} % in "
          f"compiled code ({named} functions named)")
    print(f"{'share':>6}  function (of the samples in compiled code)")
    for name, k in counts.most_common(args.top):
        print(f"{100 * k / max(jit, 1):5.1f}%  {name}")
    for name in args.annotate:
        annotate(data, entries, name, args.lines)


if __name__ == "__main__":
    main()
