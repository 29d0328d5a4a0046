"""The estimate command: Ctrl-C keeps its batches and says how to resume it, and the same
command resumes it; a SUT that hangs costs one episode within the limit given."""

import json
import os
import signal
import subprocess
import sys
import time

import pandas as pd

from tests.helpers import hazardhunt

FAST_SUT = ["--controller", "hazardhunt.benchmark.conservative:ConservativeController"]


def test_an_interrupted_estimate_says_how_to_resume_and_resumes(tmp_path):
    out = tmp_path / "estimate"
    arguments = [
        "estimate", "--scenario", "head-on", "--field", "none", "--method", "mc",
        "--episodes", 200, "--batch-size", 20, *FAST_SUT, "--out", out,
    ]  # fmt: skip
    command = [sys.executable, "-m", "hazardhunt.cli", *map(str, arguments)]
    with subprocess.Popen(
        command,
        stderr=subprocess.PIPE,
        text=True,
        env=os.environ | {"COLUMNS": "1000"},
        # As in a terminal, whatever started the tests (a shell's background job ignores it).
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    ) as process:
        try:
            deadline = time.monotonic() + 120
            while not any(out.glob("batches/*")) and time.monotonic() < deadline:
                time.sleep(0.1)
            assert any(out.glob("batches/*")), "the estimate wrote no batch"
            process.send_signal(signal.SIGINT)
            _, stderr = process.communicate(timeout=60)
        finally:
            process.kill()
    assert process.returncode == 130
    assert "Traceback" not in stderr
    assert "interrupted: run the same command again to resume" in stderr.strip().splitlines()[-1]
    kept = {path.name: path.read_bytes() for path in out.glob("batches/*")}
    # The same command plays the batches it lacks and keeps those it has.
    again = hazardhunt(*arguments)
    assert again.returncode == 0, again.stderr
    batches = {path.name: path.read_bytes() for path in out.glob("batches/*")}
    assert len(batches) == 2 * 10  # a table and a note per batch
    assert all(batches[name] == content for name, content in kept.items())


HANGS_ONCE = """
import time

from hazardhunt.benchmark.conservative import ConservativeController


class HangsInItsFirstEpisode(ConservativeController):
    def reset(self, *args):
        self.episodes = getattr(self, "episodes", 0) + 1
        super().reset(*args)

    def control(self, time_s, robot, human):
        if self.episodes == 1 and time_s >= 1.0:  # the trial episode plays on another
            time.sleep(30)
        return super().control(time_s, robot, human)
"""


def test_a_controller_that_hangs_is_one_sut_error_within_the_limit_given(tmp_path):
    (tmp_path / "hangs.py").write_text(HANGS_ONCE)
    out = tmp_path / "estimate"
    done = hazardhunt(
        "estimate", "--scenario", "head-on", "--field", "none", "--method", "mc",
        "--episodes", 100, "--controller", "hangs:HangsInItsFirstEpisode",
        "--controller-timeout", 0.5, "--out", out, cwd=tmp_path,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    estimate = json.loads((out / "estimate.json").read_text())
    assert (estimate["episodes"], estimate["sut_errors"]) == (100, 1)
    # The controller's first episode is the estimate's first, as in a worker process of its own.
    played = pd.concat(pd.read_parquet(batch) for batch in sorted(out.glob("batches/*.parquet")))
    assert list(played["sut_error"]).index(True) == 0
    assert "time limit of 0.5 s" in estimate["first_sut_error"]
    refused = hazardhunt("estimate", "--controller-timeout", -1, "--out", tmp_path / "other")
    assert refused.returncode == 2
    assert refused.stderr.strip() == "error: controller_timeout: must be greater than 0"
    assert not (tmp_path / "other").exists()
