"""The nine-case table's script: how often each method leads, from the peers' result files."""

import json
import subprocess
import sys
from pathlib import Path

SCRIPT = Path(__file__).parents[1] / "benchmarks" / "peers" / "nine.py"


def run(method: str, case: str, classes: list[str], seed: int = 0) -> dict[str, object]:
    return {"method": method, "case": case, "seed": seed, "classes": classes, "failures": 1}


def leaders(files: list[Path], default: str) -> dict[str, tuple[int, int]]:
    result = subprocess.run(
        [sys.executable, str(SCRIPT), *map(str, files), "--seed", "0", "--default", default],
        capture_output=True,
        text=True,
        timeout=60,
        check=True,
    )
    table = result.stdout.split("over the 2 cases:")[1]
    rows = [line.split("|")[1:4] for line in table.splitlines() if line.startswith("| `")]
    return {name.strip(" `"): (int(ge), int(union)) for name, ge, union in rows}


def test_each_method_is_held_against_every_other_but_the_default(tmp_path):
    runs = [
        run("portfolio", "a", ["x", "y"]),
        run("portfolio", "b", ["x", "other"]),
        run("cem", "a", ["x"]),
        run("cem", "b", ["x", "z"]),
        run("random", "a", ["y"]),
        run("random", "b", ["z"]),
        run("cem", "a", ["x", "y", "z"], seed=1),  # another seed: not counted
        run("qd", "a", ["x", "y", "z"]),  # not measured in every case: a rival, not listed
    ]
    file = tmp_path / "peers.json"
    file.write_text(json.dumps({"runs": runs}))

    board = leaders([file], default="portfolio")

    # a: qd's three classes beat everyone; b: cem's two ("other" does not count) lead, and
    # the union there is x and z, which only cem has.
    assert board == {"portfolio": (0, 0), "cem": (1, 1), "random": (0, 0)}
