"""Result files: the atomic writers (nothing half-written, no temporary left behind) and the reports' JSON."""
from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from cemnet_ros.io.atomic import atomic_file, json_text, write_report
from cemnet_ros.io.report import Report, emit


def test_atomic_file_replaces_only_on_success(tmp_path):
    target = tmp_path / "w.bin"
    target.write_bytes(b"old")
    with pytest.raises(RuntimeError), atomic_file(target) as handle:
        handle.write(b"half")
        raise RuntimeError("crash mid-write")
    assert target.read_bytes() == b"old" and os.listdir(tmp_path) == ["w.bin"]
    with atomic_file(target) as handle:
        handle.write(b"new")
    assert target.read_bytes() == b"new" and os.listdir(tmp_path) == ["w.bin"]
    assert oct(target.stat().st_mode & 0o777) == oct(0o644)


def test_write_report_makes_the_folder(tmp_path):
    path = write_report(tmp_path / "a" / "b" / "r.md", "| x |\n")
    assert path.read_text() == "| x |\n"


def test_json_text_is_strict_json():
    text = json_text({"a": np.arange(3), "b": np.float32(0.5), "c": float("nan"), "d": Path("x/y"), 1: (np.inf,)})
    assert json.loads(text) == {"a": [0, 1, 2], "b": 0.5, "c": None, "d": "x/y", "1": [None]}
    assert text.endswith("\n") and "NaN" not in text


@dataclass
class _Counted(Report):
    name: str
    values: np.ndarray

    def to_markdown(self) -> str:
        return f"| {self.name} | {self.values.sum()} |"


def test_emit_prints_the_markdown_and_writes_the_json(tmp_path, capsys):
    report = _Counted("n", np.array([1, 2]))
    emit(report, tmp_path / "out" / "r.json")
    assert capsys.readouterr().out == "| n | 3 |\n"
    assert json.loads((tmp_path / "out" / "r.json").read_text()) == {"name": "n", "values": [1, 2]}
    emit(report)  # no JSON path: printed only
    assert capsys.readouterr().out == "| n | 3 |\n" and os.listdir(tmp_path) == ["out"]
