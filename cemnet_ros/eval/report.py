"""The result of one evaluation run: aggregates and per-pair figures per method, as markdown or JSON."""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any, Dict, List

from cemnet_ros.io.atomic import jsonable

# (header, aggregate key, format)
COLUMNS = (
    ("MAE(R) deg", "r_mae_deg", "{:.4f}"), ("RMSE(R) deg", "r_rmse_deg", "{:.4f}"),
    ("MAE(t)", "t_mae", "{:.6f}"), ("RMSE(t)", "t_rmse", "{:.6f}"),
    ("iso R err deg (mean)", "rot_err_deg_mean", "{:.4f}"), ("iso t err (mean)", "trans_err_mean", "{:.6f}"),
    ("recall", "recall", "{:.3f}"), ("median ms/pair", "median_ms_per_pair", "{:.1f}"),
)


def markdown_table(aggregates: Dict[str, Dict[str, float]], title: str) -> str:
    """Markdown table, one row per method."""
    lines = [f"### {title}", "", "| method | " + " | ".join(c[0] for c in COLUMNS) + " |",
             "|---|" + "---:|" * len(COLUMNS)]
    for method, agg in aggregates.items():
        lines.append(f"| {method} | " + " | ".join(fmt.format(agg[key]) for _, key, fmt in COLUMNS) + " |")
    return "\n".join(lines) + "\n"


@dataclass
class Report:
    """Every method's figures on the same pairs.

    ``aggregates`` and ``per_pair`` are keyed by method (``cemnet``, ``icp``, ``fpfh``); ``row_names`` says
    how a method's row is labelled in the table (e.g. ``cemnet (network only)``); ``config`` records how
    the run was made (protocol, registration, clouds, versions).
    """

    title: str
    aggregates: Dict[str, Dict[str, float]]
    per_pair: Dict[str, List[Dict[str, Any]]]
    config: Dict[str, Any]
    row_names: Dict[str, str] = field(default_factory=dict)

    def to_markdown(self) -> str:
        shown = {self.row_names.get(m, m): agg for m, agg in self.aggregates.items()}
        return markdown_table(shown, self.title)

    def to_json(self) -> str:
        report = {"config": self.config, "aggregates": self.aggregates, "per_pair": self.per_pair}
        return json.dumps(jsonable(report), indent=1) + "\n"
