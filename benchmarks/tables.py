"""The benchmark's markdown: one table per kind of result, the accepted-while-wrong and failure lists, and the
definitions of every figure."""
from __future__ import annotations

import numpy as np

from benchmarks.metrics import PRECISE_DEG, PRECISE_M, RECALL_DEG, RECALL_M

TOL = f"{PRECISE_M} m / {PRECISE_DEG} deg"
DEFINITIONS = "\n".join([
    "Definitions. RTE / RRE: translation (m) / rotation angle (deg) of inv(T_true) @ T_est for a step's relative",
    "motion (pairs: scan 1 -> scan 2; sequences: previous processed scan -> this scan).",
    f"recall: RTE < {RECALL_M} m and RRE < {RECALL_DEG} deg; precise: RTE < {PRECISE_M} m and RRE < {PRECISE_DEG} deg;",
    "both over ALL steps whatever their flag (failed = exception or no earlier processed scan: a miss).",
    f"flagged: accepted False. accepted wrong: accepted and (RTE > {PRECISE_M} m or RRE > {PRECISE_DEG} deg);",
    "peers accept every step. ms: wall time of the call that produced the step (median / p90).",
    "ATE: position RMSE with both trajectories expressed in their first pose's frame (no other alignment).",
    "drift: end position error / driven distance (the kidnap's teleport is not driven).",
    "Events: e = the first delivered scan after the event, a = the last delivered scan before it, candidates =",
    "the first two delivered scans at or after e.",
    f"recovered: a candidate is accepted and its pose relative to a is within {TOL} of the truth",
    "(the trajectory is still right across the event; after a kidnap that needs a re-localisation).",
    f"resumed: a candidate is accepted and its own step is within {TOL} (tracking goes on).",
    "kidnap flagged: scan e (the first teleported scan) is not accepted.",
])
EVENT_KINDS = ["dropout", "stop", "go", "yaw_swing", "yaw_reverse", "kidnap"]


def _f(value, fmt: str = ".3f") -> str:
    return "-" if value is None else format(value, fmt)


def _pct(value, digits: int = 0) -> str:
    return "-" if value is None else f"{100 * value:.{digits}f}%"


def _method_results(results: dict):
    """(set name, method, result) over every set: a set is {method: result} or {"methods": {...}, ...}."""
    for set_name, data in results.items():
        for name, res in (data.get("methods", data) if isinstance(data, dict) else {}).items():
            yield set_name, name, res


def main_table(results: dict) -> str:
    """One row per (set, method) of the step summaries."""
    lines = ["| set | method | steps | failed | flagged | recall | precise | accepted wrong | RTE med (m) | "
             "RRE med (deg) | ms med | ms p90 |", "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for set_name, name, res in _method_results(results):
        if not isinstance(res, dict) or "summary" not in res:
            continue
        s = res["summary"]
        lines.append(f"| {set_name} | {name} | {s['steps']} | {s['failed']} | {s['flagged']} | {_pct(s['recall'])} "
                     f"| {_pct(s['precise'])} | {s['accepted_wrong']} | {_f(s['rte_median_accepted_m'])} | "
                     f"{_f(s['rre_median_accepted_deg'], '.2f')} | {_f(s['ms_median'], '.0f')} | "
                     f"{_f(s['ms_p90'], '.0f')} |")
    return "\n".join(lines)


def wrong_list(results: dict) -> str:
    """Every accepted-while-wrong step, one line per (set, method)."""
    lines = []
    for set_name, name, res in _method_results(results):
        if isinstance(res, dict) and res.get("summary", {}).get("accepted_wrong_steps"):
            items = ", ".join(f"{w['case']}@{w['index']} ({w['rte_m']:.2f} m, {w['rre_deg']:.1f} deg)"
                              for w in res["summary"]["accepted_wrong_steps"])
            lines.append(f"- {set_name} / {name}: {items}")
    return "\n".join(["Accepted while wrong:"] + lines) if lines else "Accepted while wrong: none"


def failure_list(results: dict) -> str:
    """The distinct exception messages (first line) per (set, method)."""
    lines = []
    for set_name, name, res in _method_results(results):
        errors = res.get("summary", res).get("errors") if isinstance(res, dict) else None
        for error in sorted({e.splitlines()[0] for e in errors or []}):
            lines.append(f"- {set_name} / {name}: {error}")
    return "\n".join(["Failures (exceptions):"] + lines) if lines else "Failures (exceptions): none"


def _mean(sequences: list[dict], key: str):
    values = [s[key] for s in sequences if s[key] is not None]
    return float(np.mean(values)) if values else None


def sequence_table(data: dict) -> str:
    """Per method: ATE, drift and event outcomes (recovered / resumed per event kind) over all drives."""
    lines = ["| method | ATE (m) | ATE before kidnap (m) | drift % | drift before kidnap % | "
             + " | ".join(f"{k} rec/res" for k in EVENT_KINDS) + " | kidnap flagged |",
             "|---|---|---|---|---|" + "---|" * len(EVENT_KINDS) + "---|"]
    for name, res in data["methods"].items():
        seqs = res["sequences"]
        events = [e for s in seqs for e in s["events"]]
        cells = []
        for kind in EVENT_KINDS:
            ev = [e for e in events if e["kind"] == kind and e["recovered"] is not None]
            cells.append(f"{sum(e['recovered'] for e in ev)}/{sum(e['resumed'] for e in ev)} of {len(ev)}")
        kid = [e for e in events if e["kind"] == "kidnap" and e["flagged"] is not None]
        lines.append(f"| {name} | {_f(_mean(seqs, 'ate_m'))} | {_f(_mean(seqs, 'ate_before_kidnap_m'))} | "
                     f"{_f(_mean(seqs, 'drift_pct'), '.1f')} | {_f(_mean(seqs, 'drift_before_kidnap_pct'), '.1f')} | "
                     + " | ".join(cells) + f" | {sum(e['flagged'] for e in kid)} of {len(kid)} |")
    return "\n".join(lines)


def corridor_table(data: dict) -> str:
    """Per method: flagged fraction, along-corridor motion recovered, covariance x vs y std."""
    lines = ["| method | flagged | along-corridor motion recovered | x std med (m) | y std med (m) | "
             "x/y std med | steps with x std > y std |", "|---|---|---|---|---|---|---|"]
    for name, r in data.items():
        lines.append(f"| {name} | {_pct(r['flagged_fraction'])} | {_pct(r['along_recovered'], 1)} | "
                     f"{_f(r['x_std_median_m'], '.4f')} | {_f(r['y_std_median_m'], '.4f')} | "
                     f"{_f(r['x_over_y_std_median'], '.2f')} | {_pct(r['x_std_larger_fraction'])} |")
    return "\n".join(lines)


def fast_gaps_table(data: dict) -> str:
    """Per method: the drives' ATE (median, worst), how many held within the precise tolerance, steps flagged."""
    lines = [f"| method | drives | ATE med (m) | ATE max (m) | ATE < {PRECISE_M} m | flagged steps |",
             "|---|---|---|---|---|---|"]
    for name, r in data.items():
        ates = [d["ate_m"] for d in r["drives"] if d["ate_m"] is not None]
        held = sum(a < PRECISE_M for a in ates)
        lines.append(f"| {name} | {len(r['drives'])} | {_f(float(np.median(ates)) if ates else None)} | "
                     f"{_f(max(ates) if ates else None)} | {held} | {sum(d['flagged'] for d in r['drives'])} |")
    return "\n".join(lines)


def speed_table(data: dict) -> str:
    """ms per scan of each method on the KITTI ping-pong stream, and the ratio."""
    lines = [f"KITTI {data['points_mean']} points/scan, {data['scans']} scans, first {data['warmup']} excluded",
             "| method | ms med | ms p90 | scans timed |", "|---|---|---|---|"]
    for name in ("cemnet", "kiss-icp"):
        if name in data:
            r = data[name]
            lines.append(f"| {name} | {_f(r['ms_median'], '.0f')} | {_f(r['ms_p90'], '.0f')} | {r['timed']} |")
    if "ratio_cemnet_over_kiss" in data:
        lines.append(f"\nms per scan, cemnet / kiss-icp: {data['ratio_cemnet_over_kiss']:.2f}x")
    return "\n".join(lines)


def report_markdown(results: dict) -> str:
    """Every table of the results measured so far (``results``: set name -> that set's result), then the
    definitions."""
    parts = [main_table({k: v for k, v in results.items() if k != "speed"}), wrong_list(results),
             failure_list(results)]
    if "sequences" in results:
        parts.append("Sequences (recovered/resumed of events):\n" + sequence_table(results["sequences"]))
    if "corridor" in results:
        parts.append("Corridor:\n" + corridor_table(results["corridor"]))
    if "fast_gaps" in results:
        parts.append("Fast gaps (a car at 15-25 m/s, one gap of 0.5-1 s):\n" + fast_gaps_table(results["fast_gaps"]))
    if "speed" in results:
        parts.append("Speed:\n" + speed_table(results["speed"]))
    return "\n\n".join(parts + [DEFINITIONS])
