"""``shapemotion bodies``: protocol and single-body outputs, contact sheet, exit codes."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.slow
EXP1 = Path(__file__).resolve().parents[1] / "protocols" / "exp1_shape_motion.yaml"

DESIGN_COLUMNS = ["body_id", "sex", "target_height_m", "target_bmi", "height_m", "mass_kg", "bmi", "waist_m",
                  "n_vertices", "n_faces", "mesh"]


@pytest.fixture(scope="module")
def protocol_run(tmp_path_factory):
    """Run the protocol command twice into two folders (the second from the cache)."""
    from stimuli.cli import main

    root = tmp_path_factory.mktemp("bodies")
    codes = [main(["bodies", str(EXP1), "--out", str(root / name)]) for name in ("a", "b")]
    return codes, root


def test_protocol_outputs(protocol_run):
    import trimesh

    codes, root = protocol_run
    assert codes == [0, 0]
    with open(root / "a" / "bodies.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert list(rows[0]) == DESIGN_COLUMNS
    assert len(rows) == 12 and {r["body_id"] for r in rows} >= {"F_Hi1", "M_Lo2"}
    for row in rows:
        assert abs(float(row["height_m"]) - float(row["target_height_m"])) <= 0.01
        assert abs(float(row["bmi"]) - float(row["target_bmi"])) <= 0.5
        mesh = trimesh.load(root / "a" / row["mesh"], process=False)
        assert len(mesh.vertices) == int(row["n_vertices"]) and len(mesh.faces) == int(row["n_faces"]) > 10_000
        assert float(np.min(mesh.vertices[:, 1])) == pytest.approx(0.0, abs=1e-6)
    with open(root / "a" / "segments.csv", newline="") as handle:
        segments = list(csv.DictReader(handle))
    assert len(segments) == 12 * 15


def test_outputs_are_byte_identical_across_runs(protocol_run):
    _, root = protocol_run
    for name in ("bodies.csv", "anthropometry.csv", "segments.csv", "meshes/F_Hi1.ply"):
        assert (root / "a" / name).read_bytes() == (root / "b" / name).read_bytes(), name


def test_contact_sheet_shows_every_body_sorted_by_bmi(protocol_run):
    import imageio.v3 as iio

    from stimuli.bodies.contact_sheet import TILE_H, TILE_W

    _, root = protocol_run
    image = iio.imread(root / "a" / "contact_sheet.png")
    assert image.shape[1] == 12 * TILE_W and image.shape[0] > 2 * TILE_H
    top = 34  # title band
    areas = []
    for i in range(12):
        tile = image[top:top + TILE_H, i * TILE_W + 2:(i + 1) * TILE_W - 2, :3].astype(int)
        body = (np.abs(tile - 255).sum(axis=2) > 60)          # non-white pixels: the body
        assert 0.03 < body.mean() < 0.5, f"tile {i} is empty or flooded"
        areas.append(body.sum())
    # Sorted by BMI: the last tile (M_Hi2, 1.83 m, BMI 35.8) covers far more than the first (F_Lo2, 1.60 m, 19.5).
    assert areas[-1] > 1.5 * areas[0]


def test_single_body(tmp_path, run_cli):
    import json

    import trimesh

    out = tmp_path / "x.ply"
    code, stdout, _ = run_cli("bodies", "--sex", "F", "--height", "1.6", "--bmi", "28.1", "--out", out,
                              "--json", tmp_path / "x.json")
    assert code == 0 and "BMI 28.1" in stdout
    mesh = trimesh.load(out, process=False)
    assert mesh.bounds[1, 1] - mesh.bounds[0, 1] == pytest.approx(1.6, abs=0.01)
    report = json.loads((tmp_path / "x.json").read_text())
    assert report["fit"]["reachable"] and len(report["segments"]) == 15


@pytest.mark.parametrize("args, message", [
    (["--height", "1.6", "--bmi", "28", "--out", "x.ply"], "--sex"),
    (["--sex", "F", "--height", "1.6", "--bmi", "58", "--out", "x.ply"], "out of reach"),
    (["--sex", "M", "--height", "1.2", "--bmi", "25", "--out", "x.ply"], "nearest body"),
    (["--sex", "F", "--height", "1.6", "--bmi", "80", "--out", "x.ply"], "outside the human range 13–60"),
    (["--sex", "M", "--height", "3.0", "--bmi", "25", "--out", "x.ply"], "outside the human range 1.2–2.3 m"),
    (["--sex", "F", "--height", "1.6", "--bmi", "28", "--out", "x.ply", "--backend", "smpl-y"], "backend"),
    (["--sex", "Q", "--height", "1.6", "--bmi", "28", "--out", "x.ply"], "sex must be"),
    (["--sex", "F", "--height", "1.6", "--bmi", "28", "--out", "x.txt"], "mesh file"),
    ([str(EXP1), "--sex", "F", "--out", "d"], "not both"),
    (["no_such_protocol.yaml", "--out", "d"], "no_such_protocol"),
])
def test_user_errors_exit_2(tmp_path, monkeypatch, run_cli, args, message):
    monkeypatch.chdir(tmp_path)
    code, _, err = run_cli("bodies", *args)
    assert code == 2 and message in err.replace("\n", " ")
