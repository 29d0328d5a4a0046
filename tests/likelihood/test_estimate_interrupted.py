"""Ctrl-C on an estimate keeps its batches and says how to resume it; the same command
resumes it."""

import os
import signal
import subprocess
import sys
import time

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
