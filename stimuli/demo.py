"""``shapemotion demo``: the whole chain on the bundled protocols, step by step."""

from __future__ import annotations

from pathlib import Path

from stimuli.design import build_design, write_design
from stimuli.protocol import load_protocol

PROTOCOL_DIR = Path(__file__).resolve().parents[1] / "protocols"
BUNDLED = ["exp1_shape_motion", "exp2_com_vs_average", "thesis_pointlight", "thesis_validation"]


def bundled_protocol(name: str) -> Path:
    return PROTOCOL_DIR / f"{name}.yaml"


def run_demo(out: Path, quick: bool = False) -> list[Path]:
    """Run every available step for each bundled protocol; print and return what was made."""
    made: list[Path] = []
    for name in BUNDLED:
        protocol = load_protocol(bundled_protocol(name))
        design = build_design(protocol)
        files = write_design(design, Path(out) / name)
        tests = sum(s.kind == "test" for s in design.stimuli)
        print(f"[design] {name}: {tests} test stimuli, {len(design.trials)} trials for "
              f"{design.participants} participants → {Path(out) / name}")
        made += files
    return made
