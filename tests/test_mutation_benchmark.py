"""The mutation benchmark's entry point, with a tiny budget."""

import json
import subprocess
import sys
from pathlib import Path

BENCHMARK = Path(__file__).parents[1] / "benchmarks" / "mutants.py"


def benchmark(*args: object) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, str(BENCHMARK), *map(str, args)],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )


def test_the_benchmark_scores_a_tester_and_writes_its_results(tmp_path):
    out = tmp_path / "mutants.json"
    result = benchmark(
        "--testers", "random", "--scenarios", "head-on", "--fields", "none",
        "--mutants", "BlindRightRear",
        "--episodes", 2, "--early", 1, "--workers", 1, "--out", out,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert "false alarms" in result.stdout
    written = json.loads(out.read_text())
    assert "--testers random" in written["command"]
    assert {run["sut"] for run in written["runs"]} == {"ConservativeController", "BlindRightRear"}
    (score,) = written["scores"]
    assert score["false_alarms"] == 0
    assert score["scenarios"]["head-on"]["mutants"] == 1
    (total,) = written["totals"]
    mutant_runs = [run for run in written["runs"] if run["sut"] == "BlindRightRear"]
    assert total["failures"] == sum(run["failures"] for run in mutant_runs)
    assert f"{total['failures']} failures" in result.stdout


def test_a_tester_that_cannot_be_configured_stops_the_benchmark_before_it_runs(tmp_path):
    result = benchmark(
        "--testers", "no.such:Tester", "--episodes", 1, "--early", 1, "--out", tmp_path / "x"
    )  # fmt: skip
    assert result.returncode == 1
    assert "no.such:Tester" in result.stderr
    assert not (tmp_path / "x").exists()
