"""A small sweep: the paper's reach with two energy weights and two random hand gains.

A campaign names a base scenario and the keys to vary; `run_sweep` runs every case as an
ordinary run on local worker processes, writes one result file per case as it ends, then
`results.csv`, `best.md` and the plots. Here 2 x 2 = 4 cases of the reach cut to 5 % of its
duration (a smoke test of the machinery, not of the reach) on two workers.

    python examples/small_sweep.py [--out DIR]
"""

import argparse
import tempfile
from pathlib import Path

from wholebody.sweep import load_campaign, run_sweep

CAMPAIGN = """
format = 1
[campaign]
name = "example_sweep"
scenario = "reach_generalisation"
duration_scale = 0.05
samples = 2
seed = 7

[[axes]]
key = "stack.energy"
values = [0.0, 0.5]

[[axes]]
key = "hands.right.kp"
uniform = [10.0, 30.0]
"""

if __name__ == "__main__":  # the workers are spawned processes: they import this file
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, help="where the results go (default: a temp dir)")
    parser.add_argument("--viz", action="store_true", help="(nothing to show: see best.md)")
    args = parser.parse_args()
    out = args.out or Path(tempfile.mkdtemp(prefix="wholebody-sweep-"))
    path = out / "campaign.toml"
    out.mkdir(parents=True, exist_ok=True)
    path.write_text(CAMPAIGN)
    result = run_sweep(load_campaign(path), out / "results", workers=2, progress=False)
    for row in result.rows:
        step = row["step_time_us/median"]
        print(
            f"case {row['index']}: energy {row['stack.energy']}, kp {row['hands.right.kp']:.1f}: "
            f"{row['status']}, {row['steps']} steps, median step {step:.0f} us"
        )
    print(f"{result.cases} cases in {result.wall_time:.1f} s; table: {result.files['table']}")
    assert result.cases == 4 and result.ran == 4, f"4 cases should run, {result.ran} did"
    assert all(r["status"] == "ok" for r in result.rows), "every case should end ok"
    assert (out / "results" / "best.md").exists(), "the report should be written"
