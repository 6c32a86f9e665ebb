"""The library benchmark's figures as markdown tables (``docs/libraries.md`` reads them)."""
from __future__ import annotations

from typing import Callable, Optional

from benchmarks.libraries.peers import OURS


def _f(value: Optional[float], fmt: str = ".1f") -> str:
    return "-" if value is None else format(value, fmt)


def _ratios(name: str, row: dict) -> str:
    """``ours / method | same, quiet rounds (their count)`` cells (1 for ours)."""
    quiet = row.get("quiet_rounds", "-")
    if name == OURS:
        return f"1 | 1 ({quiet})"
    return f"{_f(row.get('ours_over'), '.2f')} | {_f(row.get('ours_over_quiet'), '.2f')} ({quiet})"


def speed_rows(piece: str, sequence: str, summary: dict[str, dict], extra: Callable[[str], str]) -> list[str]:
    """Markdown rows ``| piece | sequence | method | ms | ours / method | quiet | extra |``."""
    return [f"| {piece} | {sequence} | {name} | {_f(row['ms_median'])} | {_ratios(name, row)} | {extra(name)} |"
            for name, row in summary.items()]


def libraries_table(results: dict) -> str:
    """The measured figures as one markdown table per piece family (speed; polish accuracy; start-up)."""
    rows = ["| piece | sequence | method | ms median | ours / method | quiet rounds | notes |",
            "|---|---|---|---|---|---|---|"]
    for seq, r in results["sequences"].items():
        down = r["downsample"]
        rows += speed_rows("downsample", seq, down["ms"],
                           lambda n: f"{down['points_in']} -> {down['points_out'][n]} points")
        rows += speed_rows("map update", seq, r["map_update"]["ms"], lambda n: "")
        near = r["nearest"]
        rows += speed_rows("nearest", seq, near["ms"],
                           lambda n: f"agrees with ours {100 * near['agreement'][n]:.2f} %"
                           + (f", tree build {_f(near['build_ms'][n]['ms_median'])} ms" if n in near["build_ms"]
                              else ""))
    rows += ["", "| sequence | map | start offset | method | ms median | ours / method | quiet rounds | steps "
             "| RTE median cm | RRE median deg | within 10 cm / 1 deg |", "|---" * 11 + "|"]
    for seq, r in results["sequences"].items():
        for label, offsets in r["polish"].items():
            for offset, methods in offsets.items():
                for name, m in methods.items():
                    rows.append(f"| {seq} | {label} | {offset} | {name} | {_f(m['ms_median'])} | {_ratios(name, m)} | "
                                f"{_f(m['iterations_median'], '.0f')} | {_f(100 * m['rte_median_m'], '.2f')} | "
                                f"{_f(m['rre_median_deg'], '.3f')} | {100 * m['success']:.0f} % ({m['trials']}) |")
    if results.get("startup"):
        keys = sorted({k for v in results["startup"].values() for k in v})
        rows += ["", "| start-up (fresh process) | " + " | ".join(keys) + " |", "|---" * (len(keys) + 1) + "|"]
        for library, figures in results["startup"].items():
            rows.append(f"| {library} | " + " | ".join(_f(figures.get(k)) for k in keys) + " |")
    return "\n".join(rows)
