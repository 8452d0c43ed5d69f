"""``biped-opt bench``: loading the checkout's bench package, output, and the no-checkout error."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from biped_opt.cli import bench_cmd
from biped_opt.cli.main import main


def test_load_bench_finds_the_checkout() -> None:
    module = bench_cmd.load_bench()
    assert Path(module.__file__).parent == bench_cmd.checkout_root() / "bench"
    assert callable(module.run_benchmark)


def test_entry_point_imports_bench_outside_the_checkout(tmp_path: Path) -> None:
    # a fresh interpreter in an unrelated directory: the checkout is not on sys.path there
    code = (
        "import sys\nfrom biped_opt.cli.bench_cmd import load_bench\n"
        "assert 'bench' not in sys.modules\nprint(load_bench().__name__)"
    )
    proc = subprocess.run(
        [sys.executable, "-I", "-c", code], cwd=tmp_path, capture_output=True, text=True,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "bench.run"


def test_missing_checkout_is_a_one_line_error(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr(bench_cmd, "checkout_root", lambda: tmp_path)
    assert main(["bench", "--quick"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "source checkout" in err


def test_bench_json(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "--quick", "--cases", "2", "--no-compile", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["n_cases"] == 2
    assert result["per_trajectory_s"]["biped_opt"] > 0


def test_bench_table(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "--quick", "--cases", "2", "--no-compile"]) == 0
    out = capsys.readouterr().out
    for word in ("biped_opt", "solve_ivp", "relaxation", "sweep", "cached"):
        assert word in out


def test_cases_must_be_at_least_two(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["bench", "--cases", "1"])
    assert exc.value.code == 2
    assert "--cases must be between 2 and 1000000" in capsys.readouterr().err


def test_bench_systems_prints_the_side_by_side_table(capsys) -> None:
    assert main(["bench", "--system", "rocking_bar", "--quick", "--no-compile", "--cases", "4",
                 "--json"]) == 0
    row = json.loads(capsys.readouterr().out)["systems"]["rocking_bar"]
    assert row["max_abs_error"] < 1e-9 and row["speedup_vs_reference"] > 1.0
