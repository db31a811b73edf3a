"""``mcl log info``: what a CARMEN log holds and what a run would take from it, with the checks a run makes before
it starts; and those checks for ``mcl bag info`` too (:func:`scan_checks`, :func:`check_lines`).

The checks are the run's own, on the scans it would read: the beams that read the robot itself
(``mcl.datasets.selfhits``), the odometry's sign and scale and the laser's mounting (``mcl.odomcheck``), each laser
of a fused stream on its own, and the scans' stamps against the odometry's (``mcl.latency``).
"""

from __future__ import annotations

import math

import numpy as np

from mcl.errors import DataError

__all__ = ["scan_checks", "check_lines", "log_info", "format_log_info"]


def scan_checks(scans, odometry, sensor, wheel_odometry: bool = True) -> dict:
    """"self_hits" (None: none found), "odometry_sideways" (``mcl.motion.sideways_share``: share, travel_m, omni;
    None for laser odometry), "odometry_check" (absent for laser odometry, ``wheel_odometry`` False) and
    "time_offset_check" (absent for laser odometry, or when the odometry check found a fault) of ``scans``, each
    laser's as a run finds them (``mcl.datasets.selfhits.summary_of``, ``mcl.odomcheck.summary_of``: fused lasers'
    others in ``other_lasers``), with the line a run would say as "text". ``odometry``: rows (t, x, y, theta, ...)
    of the odometry stream the scans' turns are timed against; None: the scans' own poses (a CARMEN log without
    ODOM lines). ``sensor``: a SensorConfig (range_min, range_max, laser_pose, upside_down, misfit_laser); None:
    the defaults."""
    from mcl.config import SensorConfig
    from mcl.datasets.selfhits import beam_constancies, self_hits_of
    from mcl.datasets.selfhits import summary_of as hits_summary
    from mcl.estimate import compose
    from mcl.latency import check_each_laser as check_times
    from mcl.latency import findings as time_findings
    from mcl.latency import summary_of as time_summary
    from mcl.motion import SIDEWAYS_OMNI, sideways_share
    from mcl.odomcheck import check_each_laser, findings, run_mount
    from mcl.odomcheck import summary_of as odometry_summary

    sensor = SensorConfig() if sensor is None else sensor
    sideways = None  # laser odometry's jitter reads as sideways travel: not measured (mcl.runner._choose_motion_model)
    if wheel_odometry:
        poses = (np.asarray(odometry, dtype=np.float64).reshape(-1, 6)[:, 1:4] if odometry is not None
                 else np.array([s.odom for s in scans if s.odom is not None], dtype=np.float64).reshape(-1, 3))
        share, travel = sideways_share(poses)
        sideways = {"share": round(share, 4), "travel_m": round(travel, 1), "omni": share >= SIDEWAYS_OMNI}
    units = []
    if wheel_odometry:
        from mcl.odomcheck import odometry_units

        rows = (np.asarray(odometry, dtype=np.float64).reshape(-1, 6) if odometry is not None else
                np.array([(s.t, *s.odom) for s in scans if s.odom is not None], dtype=np.float64).reshape(-1, 4))
        units = odometry_units(rows[np.argsort(rows[:, 0], kind="stable")])
    hits = [h for h in (self_hits_of(c) for c in beam_constancies(scans, float(sensor.range_min),
                                                                   float(sensor.range_max))) if h is not None]
    out = {"self_hits": hits_summary(hits), "odometry_sideways": sideways, "odometry_units": units}
    for h, d in zip(hits, [out["self_hits"], *(out["self_hits"] or {}).get("other_lasers", [])]):
        d["text"] = h.describe()
    if wheel_odometry:  # laser odometry comes from the scans: nothing to check
        checks = list(check_each_laser(scans, lambda s: run_mount(s, sensor.laser_pose)).values())
        if checks:
            out["odometry_check"] = odometry_summary(checks)
            left_out, _, texts, turned = findings(checks, sensor)
            for c, d in zip(checks, [out["odometry_check"], *out["odometry_check"].get("other_lasers", [])]):
                if c.laser in texts:
                    d["text"] = texts[c.laser]
            if checks[0].verdict is None:
                mounts = {c.laser: compose(np.asarray(c.mount), np.array([0.0, 0.0, turned.get(c.laser, 0.0)]))
                          for c in checks if c.verdict is None and c.laser not in left_out}
                timing = check_times(scans, odometry, mounts)
                _, said = time_findings(timing, sensor.time_offset, sensor.stamp_offset == "fit")
                out["time_offset_check"] = time_summary(timing)
                for c, d in zip(timing, [out["time_offset_check"], *out["time_offset_check"].get("other_lasers", [])]):
                    d["text"] = said.get(c.laser, c.describe())
    return out


def check_lines(u: dict) -> list[str]:
    """The lines of :func:`scan_checks`' findings in ``u``, as ``mcl bag info`` and ``mcl log info`` print them."""
    lines = []
    h = u.get("self_hits")
    lines += [f"  robot itself: {d['laser']}: {d['text']}: left out (sensor.self_hit_skip)"
              for d in ([h, *h.get("other_lasers", [])] if h else [])] or [
        "  robot itself: no beam reads it (sensor.self_hit_skip)"]
    w = u.get("odometry_sideways")
    if w is not None:
        lines.append(f"  sideways:     {w['share']:.1%} of the odometry's {w['travel_m']:g} m goes across the robot's "
                     "heading: " + ("an omnidirectional base (a run takes motion.model omni: motion.sideways)"
                                    if w["omni"] else "a differential drive's (motion.model odometry)"))
    for said in u.get("odometry_units") or ():
        lines.append(f"  units:        {said}")
    c = u.get("odometry_check")
    each = [c, *c.get("other_lasers", [])] if c is not None else []
    for d in each:
        kept = d["wins"].get("recorded", 0)
        yaw = (f"; the laser's yaw {d['yaw_deg']:+.1f} +- {d['yaw_se_deg']:.1f} degrees from its mounting (sensor."
               "mount_yaw fits 2 or more)" if d.get("yaw_deg") is not None else "")
        fit = (f"the scans fit the odometry as recorded ({kept} of {d['pairs']} pairs of scans){yaw}" if d["pairs"]
               else "no pair of scans to check: the odometry never moved far enough (odometry that never moves at "
                    "all, a run replays on laser odometry)")  # not "0 of 0 pairs fit"
        lines.append("  odometry check: " + (f"{d['laser']}: " if len(each) > 1 else "") + (d.get("text") or fit))
    c = u.get("time_offset_check")
    each = [c, *c.get("other_lasers", [])] if c is not None else []
    for d in each:
        lines.append("  scan timing:  " + (f"{d['laser']}: " if len(each) > 1 and not d["text"].startswith(d["laser"])
                                            else "") + d["text"] + ("" if d["verdict"] else " (sensor.time_offset)"))
    return lines


def _round(v, nd: int = 6):
    return None if v is None else round(float(v), nd) + 0.0  # no -0.0


def laser_geometry(s, count: int, beams: list[int]) -> dict:
    """One laser stream's geometry for ``log info`` and ``bag info``, from its first scan ``s``: ``count`` scans of
    ``beams`` (the beam counts seen, sorted) beams, the field of view and first beam's bearing in degrees, the
    reading that means no return (m) and the laser's pose on the robot."""
    off = s.laser_offset
    return {
        "scans": int(count),
        "beams": beams if len(beams) > 1 else beams[0],
        "fov_deg": round(math.degrees(float(s.angle_increment) * max(int(s.ranges.size) - 1, 0)), 3),
        "angle_min_deg": round(math.degrees(float(s.angle_min)), 3),
        "max_range": _round(s.max_range, 3),
        "laser_pose": None if off is None else [_round(v) for v in off],
    }


def beams_text(d: dict) -> str:
    """``laser_geometry``'s dict ``d`` as "181 beams over 180 degrees from -90, no return at 80 m and beyond"."""
    # the scans' max_range is where a reading means no return (the log's PARAM, a line's field, a LaserScan's
    # range_max, or the threshold found under a no-return marker: 49.5 m under 50.00 m), not the laser's reach
    rmax = "none given (sensor.range_max)" if d["max_range"] is None else f"at {d['max_range']:g} m and beyond"
    beams = d["beams"] if isinstance(d["beams"], int) else f"{d['beams'][0]}..{d['beams'][-1]}"
    return f"{beams} beams over {d['fov_deg']:g} degrees from {d['angle_min_deg']:g}, no return {rmax}"


def laser_line(kind: str, d: dict) -> str:
    """``laser_geometry``'s dict ``d`` of stream ``kind`` as one line."""
    pose = "not given (sensor.laser_pose)" if d["laser_pose"] is None else str(d["laser_pose"])
    return f"laser {kind}: {d['scans']} scans, {beams_text(d)}, laser pose {pose}"


def log_info(path, laser: str = "auto", sensor=None) -> dict:
    """A CARMEN log's messages (each type's count, the skipped ones too), its time span, each laser stream (scans,
    beams, field of view, maximum range, mounting), and what a run with ``laser`` (the config key) and ``sensor``
    would use, with the checks of :func:`scan_checks` (or why it cannot). A log that cannot be read at all (a
    malformed line) raises DataError, as a run does."""
    from mcl.datasets.carmen import read_carmen

    log = read_carmen(path, need_laser=False)  # a log of ODOM lines alone is described too
    kinds = log.kinds()
    odo = np.asarray(log.odometry, dtype=np.float64).reshape(-1, 6)
    stamps = [s.t for s in log.scans] + odo[:, 0].tolist() + [m.t for m in log.landmarks]
    messages = {**kinds, **({"ODOM": int(odo.shape[0])} if odo.shape[0] else {}),
                **({"LANDMARK": len(log.landmarks)} if log.landmarks else {}),
                **{k: v for k, v in sorted(log.skipped.items()) if k != "#"}}
    lasers = {}
    for kind in kinds:
        scans = log.scans_of(kind)
        lasers[kind] = laser_geometry(scans[0], len(scans), sorted({int(s.ranges.size) for s in scans}))
    info = {"path": str(path), "messages": messages,
            "duration_s": float(max(stamps) - min(stamps)) if stamps else 0.0,
            "time_span_s": [_round(min(stamps)), _round(max(stamps))] if stamps else None,
            "lasers": lasers, "warnings": list(log.warnings)}
    try:
        scans = log.laser_stream(laser)  # DataError naming a stream the log lacks
        t = np.array([s.t for s in scans])
        info["mcl_uses"] = {
            "lasers": list(dict.fromkeys(s.kind for s in scans)),
            "scans": len(scans),
            "odometry": (f"ODOM lines ({odo.shape[0]})" if odo.shape[0] else
                         "the laser lines' own poses (no ODOM lines)"),
            "scan_span_s": [_round(t.min()), _round(t.max())],
            # the ODOM lines' span beside the scans', as `mcl bag info` gives the odometry's (None: the laser
            # lines' own poses, which span the scans)
            "odometry_span_s": [_round(odo[:, 0].min()), _round(odo[:, 0].max())] if odo.shape[0] else None,
            "notes": list(log.notes),
            **scan_checks(scans, odo if odo.shape[0] else None, sensor),
        }
    except DataError as e:
        info["mcl_uses"] = {"error": str(e)}
    return info


def format_log_info(info: dict) -> str:
    n = sum(info["messages"].values())
    lines = [f"{info['path']}: CARMEN log, {n} messages, {info['duration_s']:.1f} s"]
    lines.append("messages:")
    w = max((len(k) for k in info["messages"]), default=0)
    lines += [f"  {k:<{w}}  {v:>8}" for k, v in info["messages"].items()]
    lines += [laser_line(kind, d) for kind, d in info["lasers"].items()]
    u = info["mcl_uses"]
    lines.append("mcl would use:")
    if "error" in u:
        lines.append(f"  nothing: {u['error']}")
    else:
        lines.append(f"  scans:        {', '.join(u['lasers'])} ({u['scans']} scans)")
        lines.append(f"  odometry:     {u['odometry']}")
        a, b = u["scan_span_s"]
        odo = u.get("odometry_span_s")
        lines.append(f"  stamps:       scans {a:.3f}..{b:.3f} s" + (f", odometry {odo[0]:.3f}..{odo[1]:.3f} s" if odo
                                                                     else ""))
        lines += check_lines(u)
        lines += [f"  note: {m}" for m in u["notes"]]
    lines += [f"  warning: {m}" for m in info["warnings"]]
    return "\n".join(lines)
