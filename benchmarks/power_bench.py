"""Power-analysis throughput: simulated data sets generated, reduced and analysed per second.

Prints, for the two paper protocols (default generative models, the paper's N = 16 and a larger N),
data sets per second of the whole vectorised path (draw → dependent measure → ANOVA of every effect),
and for comparison the per-data-set path through the importer-facing functions (simulate one data set,
compute its measure with pandas, one ANOVA call). Numbers only; nothing is asserted.

    python benchmarks/power_bench.py [--sims 2000]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def design_dir(name: str, folder: Path) -> Path:
    import contextlib
    import io

    from stimuli.cli import main
    out = folder / name
    with contextlib.redirect_stdout(io.StringIO()):
        main(["design", str(ROOT / "protocols" / f"{name}.yaml"), "--out", str(out)])
    return out


def per_dataset_rate(design, model, participants: int, repeats: int) -> float:
    """Data sets per second when each one goes through pandas measures and one anova() call."""
    from analysis.anova import anova
    from analysis.measures import AnovaInput, mean_ratings, percent_chosen
    from analysis.simulate import simulate_responses
    start = time.perf_counter()
    for seed in range(repeats):
        sim = simulate_responses(design, model, participants, seed)
        sim = sim[~sim["practice"]].merge(design.conditions.drop(columns=["practice"]), on="stimulus_id",
                                          suffixes=("", "_c"))
        sim["participant"] = sim["participant"].astype(str)
        if design.response_type == "likert":
            ai = AnovaInput(mean_ratings(sim, design.between, design.within), "rating", design.within, design.between)
        else:
            sim["chosen"] = [design.arrangement(s)[int(p) - 1] for s, p in zip(sim["stimulus_id"], sim["position"])]
            ai = AnovaInput(percent_chosen(sim, design), "percent", design.within + [design.chosen_factor], [])
        anova(ai.data, ai.dv, "participant", ai.within, ai.between)
    return repeats / (time.perf_counter() - start)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sims", type=int, default=2000)
    args = parser.parse_args()
    from analysis.io_design import load_design
    from analysis.model_spec import load_model
    from analysis.power import power_analysis
    with tempfile.TemporaryDirectory() as tmp:
        for name in ("exp1_shape_motion", "exp2_com_vs_average"):
            design = load_design(design_dir(name, Path(tmp)))
            model = load_model(None, design)
            power_analysis(design, model, 16, 50, seed=0)  # warm-up (imports, compiled design)
            for n in (16, 64):
                result = power_analysis(design, model, n, args.sims, seed=1)
                print(f"{name:22s} N={n:3d}  vectorised: {result.datasets_per_second:9.0f} data sets/s "
                      f"({args.sims} sims, {result.seconds:.2f} s, {len(result.table)} effects)")
            rate = per_dataset_rate(design, model, 16, repeats=20)
            print(f"{name:22s} N= 16  one at a time (pandas + anova()): {rate:7.1f} data sets/s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
