"""Is a simulated clip within the COM method's bounds? Warnings for a finished simulation's report.

The bounds are the acceptance of the physics (docs/readme_physics.md): a walk flies at most its
reference's own flight share + 3 points (a walk has none, but an averaged or looped capture can
read a little), a jog within 5 points of its reference's; tracking RMS at most 3° walking and 4°
jogging. A clip outside them is still written (the COM motion is what the physics gives), but the
researcher is told, naming both flight readings (the foot boxes and the contact model on the
simulated motion), since on runs the two detectors differ by several points.
"""

from __future__ import annotations

# Simulated flight share at most the reference's + (walk) or within (jog) this much, and tracking RMS (degrees).
FLIGHT_BOUND = {"walk": 0.03, "jog": 0.05}
TRACKING_BOUND_DEG = {"walk": 3.0, "jog": 4.0}
SEE = "see docs/readme_physics.md, Known limits"


def flight_excess(gait: str, flight: float, reference_flight: float) -> float:
    """How far a simulated flight share lies beyond the gait's bound around the reference's (0: within).

    >>> flight_excess("walk", 0.02, 0.0), round(flight_excess("walk", 0.094, 0.0), 3), round(flight_excess("jog", 0.2, 0.26), 3)
    (0.0, 0.064, 0.01)
    """
    kind = _kind(gait)
    off = flight - reference_flight if kind == "walk" else abs(flight - reference_flight)
    return max(0.0, off - FLIGHT_BOUND[kind])


def flight_warning(report: dict, gait: str) -> str | None:
    """A line when the simulated flight share (foot boxes) is outside the bound around the
    reference's own (``reference_flight_fraction``, 0 when the report has none); else None.

    >>> flight_warning({"flight_fraction": 0.094, "reference_flight_fraction": 0.0,
    ...                 "flight_fraction_contact_model": 0.0}, "walk")
    'no foot on the floor for 9.4 % of the walk against 0.0 % in its reference (the bound: at most 3 points more; the contact model on the simulated motion reads 0.0 %): it hops; see docs/readme_physics.md, Known limits'
    >>> flight_warning({"flight_fraction": 0.02, "reference_flight_fraction": 0.0}, "walk") is None
    True
    >>> flight_warning({"flight_fraction": 0.604, "reference_flight_fraction": 0.283,
    ...                 "flight_fraction_contact_model": 0.466}, "jog").split(" (")[0]
    'no foot on the floor for 60.4 % of the jog against 28.3 % in its reference'
    """
    flight = report.get("flight_fraction")
    if flight is None:
        return None
    reference = report.get("reference_flight_fraction") or 0.0
    if flight_excess(gait, flight, reference) == 0.0:
        return None
    if _kind(gait) == "walk":
        bound, verdict = f"at most {100 * FLIGHT_BOUND['walk']:.0f} points more", ": it hops"
    else:
        bound, verdict = f"within {100 * FLIGHT_BOUND['jog']:.0f} points of it", ""
    model = report.get("flight_fraction_contact_model")
    read = "" if model is None else f"; the contact model on the simulated motion reads {100 * model:.1f} %"
    pd_only = "controller" in report and not report["controller"].get("feedforward")
    hint = "; the PD + feed-forward controller (--controller feedforward) follows flight more closely" if pd_only else ""
    return (f"no foot on the floor for {100 * flight:.1f} % of the {gait} against {100 * reference:.1f} % in its "
            f"reference (the bound: {bound}{read}){verdict}{hint}{_out_of_reach(report, gait, reference)}; {SEE}")


def _out_of_reach(report: dict, gait: str, reference: float) -> str:
    """The clause saying that the reference's own flight is out of reach of a body that follows it, when it is.

    >>> physics = {"flight_fraction": 0.393, "pull_mps_per_s": 1.74, "pull_with_foot_down_mps_per_s": 0.88}
    >>> _out_of_reach({"reference_under_gravity": physics}, "jog", 0.300)
    '; the flight of its reference is out of reach: its centre of mass falls faster than gravity (the floor would have to pull 1.74 m/s per second, 0.88 of it with a foot down), and a body that follows it where a floor that only pushes allows is off the floor for 39.3 %'
    >>> _out_of_reach({"reference_under_gravity": {"flight_fraction": 0.31}}, "jog", 0.300)
    ''
    """
    physics = report.get("reference_under_gravity") or {}
    attainable = physics.get("flight_fraction")
    if attainable is None or flight_excess(gait, attainable, reference) == 0.0:
        return ""
    return (f"; the flight of its reference is out of reach: its centre of mass falls faster than gravity (the floor would "
            f"have to pull {physics.get('pull_mps_per_s', 0.0):.2f} m/s per second, "
            f"{physics.get('pull_with_foot_down_mps_per_s', 0.0):.2f} of it with a foot down), and a body that "
            f"follows it where a floor that only pushes allows is off the floor for {100 * attainable:.1f} %")


def tracking_warning(report: dict, gait: str) -> str | None:
    """A line when the overall tracking RMS is above the gait's bound (:data:`TRACKING_BOUND_DEG`).

    >>> tracking_warning({"tracking_rms_deg_overall": 3.4}, "jog") is None
    True
    >>> tracking_warning({"tracking_rms_deg_overall": 3.4}, "walk")[:40]
    'tracking RMS 3.40° is above 3° (the walk'
    """
    rms, bound = report.get("tracking_rms_deg_overall"), TRACKING_BOUND_DEG[_kind(gait)]
    if rms is None or rms <= bound:
        return None
    return (f"tracking RMS {rms:.2f}° is above {bound:g}° (the {gait}'s bound): the ragdoll follows this motion "
            "loosely; check the gait's gain set and the report's per-joint tracking_rms_deg")


def _kind(gait: str) -> str:
    """``walk``, or ``jog`` for any other gait (a run is driven and judged as a jog)."""
    return "walk" if gait == "walk" else "jog"


def result_warnings(report: dict, gait: str) -> list[str]:
    """Every warning about one simulated clip (flight, tracking), in that order."""
    return [w for w in (flight_warning(report, gait), tracking_warning(report, gait)) if w]
