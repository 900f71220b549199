"""benchmarks/bench_user_path.py: a sweep case run through saltation.run (chunked where the
variance samples fall, jumps collected, checkpoints written) ends in the same state, bit
for bit, as the same steps in one Stepper.advance call, with soft contacts and the contact
phase's set kept from chunk to chunk."""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent / "peers"))
import benchmark_module  # noqa: E402

REDUCED = Path(__file__).resolve().parents[1] / "cases" / "concentration_sweep_reduced.toml"


def test_a_chunked_user_run_ends_where_one_advance_call_does():
    bench = benchmark_module.load("bench_user_path")
    r = bench.compare(REDUCED, 0.52, duration=0.05)  # 364 grains, 92 steps
    assert r["steps"] == 92 and r["n"] == 364
    assert r["chunks"] > 10  # the run loop did cut the run into chunks
    assert r["kernel_s"] > 0.0 and r["direct_s"] > 0.0
    assert r["same_end_state"]
