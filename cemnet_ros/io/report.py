"""What a tool's or benchmark's ``run(config)`` returns, and how its main shows it: the markdown on stdout, the
JSON into a file (atomically)."""
from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any, Optional

from cemnet_ros.io.atomic import PathLike, json_text, write_report


@dataclass
class Report:
    """Base of the results: subclasses are dataclasses of what was measured and say how it reads."""

    def to_markdown(self) -> str:
        raise NotImplementedError

    def as_dict(self) -> dict[str, Any]:
        """What the JSON holds: the fields, unless a subclass chooses."""
        return asdict(self)

    def to_json(self) -> str:
        return json_text(self.as_dict())


def emit(report: Report, json_path: Optional[PathLike] = None) -> None:
    """Print the report's markdown; with ``json_path``, write its JSON there too (the folder made if needed)."""
    print(report.to_markdown())
    if json_path:
        write_report(json_path, report.to_json())
