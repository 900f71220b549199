"""Write tests/regression/reference.npz: the fingerprints of every case of cases.py.

Run once before a change that must not change results (python tests/regression/make_reference.py).
A change that is *meant* to move the last bits (e.g. one contact law for every contact,
with its floating-point operations in another order) re-records it deliberately, with
``--compare``: every case is reported as identical or not, and for the ones that differ
the headline numbers of summary.json (jump statistics, collisions) are printed old beside
new, so that the change is seen to be rounding, not physics. The reason goes into the
commit message and CHANGELOG.md."""
import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from cases import CASES, HERE, MACHINE, REFERENCE, STALE_COUNTERS_FILE, compare, run_case  # noqa: E402

HEADLINE = ("/jumps/count", "/jumps/H_mean", "/jumps/L_mean", "/jumps/U_mean", "/jumps/H_std", "/jumps/L_std",
            "/jumps/U_std", "/collisions/particle_particle", "/collisions/bed", "/collisions/overlap/max_over_d",
            "/collisions/overlap/mean_over_d")


def _old(name):
    if not REFERENCE.exists():
        return {}
    with np.load(REFERENCE, allow_pickle=False) as z:
        return {k.split("|", 1)[1]: z[k] for k in z.files if k.split("|", 1)[0] == name}


def _report(name, got, old):
    bad = compare(name, got, old)
    if not bad:
        print(f"{name}: identical bits")
        return
    print(f"{name}: {len(bad)} fingerprint entries differ")
    keys_new = dict(zip(got["summary/keys"], got["summary/values"], strict=True))
    keys_old = dict(zip(old.get("summary/keys", []), old.get("summary/values", []), strict=True))
    for k in HEADLINE:
        if k in keys_new or k in keys_old:
            a, b = keys_old.get(k, float("nan")), keys_new.get(k, float("nan"))
            rel = (b - a) / abs(a) if a else float("nan")
            print(f"    {k:28s} old {a:14.6g}  new {b:14.6g}  ({rel:+.2e})")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--compare", action="store_true", help="report every case against the old reference first")
    ap.add_argument("--out", default=str(HERE / "references" / f"{MACHINE}.npz"),
                    help="where to write (default: this machine's reference, references/<machine>.npz)")
    ap.add_argument("--cases", nargs="+", choices=list(CASES), metavar="NAME",
                    help="re-record only these cases, keep the others' fingerprints from the reference")
    args = ap.parse_args()
    arrays = {}
    if args.cases:
        keep = Path(args.out) if Path(args.out).exists() else REFERENCE
        with np.load(keep, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files if k.split("|", 1)[0] not in args.cases}
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.cases or CASES:
            fp = run_case(name, Path(tmp) / name)
            if args.compare:
                _report(name, fp, _old(name))
            else:
                print(name, {k: len(v) for k, v in fp.items() if k in ("jumps/particle", "tracks/particle")}, flush=True)
            arrays.update({f"{name}|{k}": v for k, v in fp.items()})
    np.savez_compressed(args.out, **arrays)
    print("wrote", args.out, Path(args.out).stat().st_size, "bytes")
    sidecar = Path(args.out).with_suffix(".json")
    if sidecar == STALE_COUNTERS_FILE and sidecar.exists():
        # the re-recorded cases' counters are current again (cases.stale_counters)
        doc = json.loads(sidecar.read_text())
        left = {}
        for part in ("stale_counters", "stale_cases"):
            stale = {k: v for k, v in doc.get(part, {}).items() if k not in (args.cases or CASES)}
            doc.pop(part, None)
            if stale:
                doc[part] = left[part] = stale
        if left:
            sidecar.write_text(json.dumps(doc, indent=2, ensure_ascii=False) + "\n")
        else:
            sidecar.unlink()
        print("stale counters and cases left:", {k: sorted(v) for k, v in left.items()} or "none")


if __name__ == "__main__":
    main()
