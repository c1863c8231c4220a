"""Files for the bodies of a protocol: bodies.csv (DESIGN.md columns), meshes/*.ply, extra tables, contact sheet."""

from __future__ import annotations

from pathlib import Path


BODIES_COLUMNS = ("body_id", "sex", "target_height_m", "target_bmi", "height_m", "mass_kg", "bmi", "waist_m",
                  "n_vertices", "n_faces", "mesh")


def _fmt(value, digits: int = 4) -> str:
    """Fixed decimals so that the same inputs give byte-identical CSV files."""
    if value is None:
        return ""
    if isinstance(value, float):
        if value != value:
            return "nan"
        text = f"{value:.{digits}f}"
        return text[1:] if text.startswith("-") and float(text) == 0.0 else text  # no "-0.0000"
    return str(value)


def body_rows(bodies) -> list[dict[str, str]]:
    """bodies.csv rows (DESIGN.md contract)."""
    rows = []
    for b in bodies:
        a = b.anthropometry
        rows.append(dict(zip(BODIES_COLUMNS, map(_fmt, (
            b.body_id, b.sex, float(b.targets["height_m"]), float(b.targets["bmi"]), a.height_m, a.mass_kg, a.bmi,
            a.waist_m, b.n_vertices, b.n_faces, f"meshes/{b.body_id}.ply")))))
    return rows


def anthropometry_rows(bodies) -> list[dict[str, str]]:
    """Every measurement and the fit report per body."""
    rows = []
    for b in bodies:
        row = {"body_id": b.body_id, "sex": b.sex}
        row.update({k: _fmt(v) for k, v in b.anthropometry.as_dict().items()})
        row.update({f"target_{k}": _fmt(None if v is None else float(v)) for k, v in b.targets.items()})
        row.update({"reachable": str(b.fit.reachable), "height_error_m": _fmt(b.fit.height_error_m, 5),
                    "bmi_error": _fmt(b.fit.bmi_error)})
        row.update({f"anny_{k}": _fmt(v, 5) for k, v in b.phenotype.items()})
        rows.append(row)
    return rows


def segment_rows(bodies) -> list[dict[str, str]]:
    """The segment table of every body, one row per body × segment."""
    return [{"body_id": b.body_id, **{k: _fmt(v, 5) for k, v in s.as_row().items()}} for b in bodies for s in b.segments]


def write_bodies(bodies, out_dir: str | Path, sheet: bool = True, title: str | None = None) -> list[Path]:
    """Write meshes/<id>.ply, bodies.csv, anthropometry.csv, segments.csv and contact_sheet.png."""
    from stimuli.fileio import csv_text, write_all_or_nothing

    out_dir = Path(out_dir)
    written = [b.save_ply(out_dir / "meshes" / f"{b.body_id}.ply") for b in bodies]
    written += write_all_or_nothing(out_dir, {
        "bodies.csv": csv_text(body_rows(bodies)),
        "anthropometry.csv": csv_text(anthropometry_rows(bodies)),
        "segments.csv": csv_text(segment_rows(bodies)),
    })
    if sheet:
        from stimuli.bodies.contact_sheet import contact_sheet

        written.append(contact_sheet(bodies, out_dir / "contact_sheet.png", title=title))
    return written
