"""Family-wise error of the post-hoc follow-ups under the null (shapemotion issue 19).

An unbalanced split-plot design — within A (2) × B (3) × C (4), between G (3 groups of 4, 6 and 8
subjects), the issue's shape — and null data sets (a random intercept per subject plus noise). For every
effect containing G (and the within main effects), follow-up (univariate, multivariate, statistica) and
adjustment (tukey, holm, bonferroni, none), the FWER of each family of pairs (within, between, mixed, all)
with its Clopper–Pearson 95 % interval, and the time taken. A second scenario breaks sphericity
(cell SDs from 0.5 to 2 across the 24 within cells), where the univariate model's assumption fails.

    .venv/bin/python benchmarks/posthoc_fwer.py [--sims 1000] [--seed 1] [--csv FILE]

Prints Markdown tables; asserts nothing (tests/test_posthoc_fwer.py checks a smaller run).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from analysis.anova_core import Design  # noqa: E402
from analysis.posthoc.fwer import null_data, null_fwer  # noqa: E402

DESIGN = Design.make(within={"A": 2, "B": 3, "C": 4}, between={"G": 3}, n_per_group=[4, 6, 8])
EFFECTS = [["A"], ["B"], ["C"], ["G"], ["A", "G"], ["B", "G"], ["C", "G"], ["A", "B", "G"], ["A", "C", "G"],
           ["B", "C", "G"]]


def run(sims: int, seed: int, cell_sd) -> tuple[object, float]:
    Y = null_data(DESIGN, sims, seed=seed, cell_sd=cell_sd)
    start = time.perf_counter()
    out = null_fwer(DESIGN, EFFECTS, Y)
    return out, time.perf_counter() - start


def markdown(out) -> str:
    """One row per effect × family, one column per follow-up × adjustment: FWER [95 % CI]."""
    cols = [(f, a) for f in ("univariate", "multivariate", "statistica")
            for a in ("tukey", "holm", "bonferroni", "none")]
    lines = ["| effect | family | pairs | " + " | ".join(f"{f} {a}" for f, a in cols) + " |",
             "|---|---|---:|" + "---:|" * len(cols)]
    for (effect, family), g in out.groupby(["effect", "family"], sort=False):
        cell = {(r.followup, r.adjust): f"{r.fwer:.3f} [{r.ci_low:.3f}, {r.ci_high:.3f}]" for r in g.itertuples()}
        lines.append(f"| {effect} | {family} | {g['pairs'].iloc[0]} | " + " | ".join(cell[c] for c in cols) + " |")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sims", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--csv", help="also write every figure to this CSV")
    args = ap.parse_args()
    print(f"design: within A2 x B3 x C4, between G3 (n = 4, 6, 8); {args.sims} null data sets per scenario; "
          "FWER = share of data sets with at least one pair at adjusted p < .05 [Clopper-Pearson 95 % CI]\n")
    frames = []
    for name, cell_sd in (("spherical (random intercept + iid noise)", 1.0),
                          ("non-spherical (cell SD 0.5 … 2)", np.linspace(0.5, 2.0, DESIGN.n_cells))):
        out, secs = run(args.sims, args.seed, cell_sd)
        out.insert(0, "scenario", name)
        frames.append(out)
        print(f"## {name}: {secs:.1f} s for {len(EFFECTS)} effects × 3 follow-ups × 4 adjustments\n")
        print(markdown(out) + "\n")
        adj = out[out["adjust"] != "none"]
        worst = adj.groupby("followup")["ci_low"].max()
        print("largest lower CI bound of an adjusted FWER, per follow-up (≤ 0.05: controlled within binomial "
              "error): " + ", ".join(f"{f} {v:.3f}" for f, v in worst.items()))
        none = out[out["adjust"] == "none"].groupby("followup")["per_pair_rate"].max()
        print("largest per-pair error of the unadjusted tests: " + ", ".join(f"{f} {v:.3f}" for f, v in none.items())
              + "\n")
    if args.csv:
        import pandas as pd
        pd.concat(frames).to_csv(args.csv, index=False)


if __name__ == "__main__":
    main()
