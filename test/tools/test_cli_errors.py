"""Bad input files end the tools with one line ``<prog>: error: <message>`` and exit status 2, no traceback."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from cemnet_ros.tools.cli_errors import reported_errors

COUNT0_BINARY_PCD = (b"VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 0 1 1\nWIDTH 2\nHEIGHT 1\n"
                     b"POINTS 2\nDATA binary\n" + b"\0" * 16)
POINTS0_BINARY_PCD = b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 0\nHEIGHT 1\nPOINTS 0\nDATA binary\n"


def test_reported_errors_one_line_and_code_2(capsys):
    with reported_errors("prog") as outcome:
        raise ValueError("first line\n  second line")
    assert outcome.code == 2
    assert capsys.readouterr().err == "prog: error: first line second line\n"
    with reported_errors("prog") as outcome:
        pass
    assert outcome.code == 0
    with reported_errors("prog", KeyError) as outcome:
        raise KeyError("k")
    assert outcome.code == 2 and "prog: error: 'k'" in capsys.readouterr().err
    with pytest.raises(ZeroDivisionError), reported_errors("prog"):  # a bug is not an input error
        1 / 0


@pytest.mark.parametrize("content, message", [
    (COUNT0_BINARY_PCD, "PCD field(s) ['x'] have COUNT 0"),
    (POINTS0_BINARY_PCD, "PCD header says 0 points"),
], ids=["count0", "points0"])
def test_register_on_a_bad_binary_pcd_exits_2_with_one_line(tmp_path, content, message):
    (tmp_path / "bad.pcd").write_bytes(content)
    np.save(tmp_path / "ok.npy", np.random.default_rng(0).normal(size=(64, 3)))
    run = subprocess.run([sys.executable, "-m", "cemnet_ros.tools.register_cli", str(tmp_path / "bad.pcd"),
                          str(tmp_path / "ok.npy")], capture_output=True, text=True, timeout=300)
    assert run.returncode == 2, run.stderr
    assert "Traceback" not in run.stderr and run.stdout == ""
    lines = run.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"cemnet-register: error: {tmp_path / 'bad.pcd'}: "), lines
    assert message in lines[0]


def test_register_main_count0_pcd_returns_2(tmp_path, capsys):
    from cemnet_ros.tools.register_cli import main

    (tmp_path / "bad.pcd").write_bytes(COUNT0_BINARY_PCD)
    assert main([str(tmp_path / "bad.pcd"), str(tmp_path / "bad.pcd")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "COUNT 0" in err


def test_train_on_a_folder_with_a_bad_scan_exits_2(tmp_path, capsys):
    from cemnet_ros.tools import train_cli

    scans = tmp_path / "scans"
    scans.mkdir()
    np.save(scans / "000000.npy", np.random.default_rng(0).normal(size=(1500, 3)))
    (scans / "000001.pcd").write_bytes(COUNT0_BINARY_PCD)
    assert train_cli.main(["--data", str(scans), "--out", str(tmp_path / "out"), "--no-progress",
                           "--device", "cpu"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err == [f"cemnet-train: error: {scans / '000001.pcd'}: PCD field(s) ['x'] have COUNT 0 (no value per "
                   "point)"]
