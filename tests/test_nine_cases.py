"""The nine-case table's script: how often each method leads, from the peers' result files."""

import json
import subprocess
import sys
from pathlib import Path

SCRIPT = Path(__file__).parents[1] / "benchmarks" / "peers" / "nine.py"
VARIANTS = Path(__file__).parents[1] / "benchmarks" / "portfolio_variants.py"


def run(method: str, case: str, classes: list[str], seed: int = 0) -> dict[str, object]:
    return {"method": method, "case": case, "seed": seed, "classes": classes, "failures": 1}


def variants_table(variants: Path, peers: Path, *options: str) -> dict[str, list[str]]:
    """``portfolio_variants.py``'s Markdown table: row label -> cells."""
    argv = [sys.executable, str(VARIANTS), str(variants), str(peers), *options]
    done = subprocess.run(argv, capture_output=True, text=True, timeout=60, check=True)
    return {
        cells[1].strip(): [cell.strip() for cell in cells[2:-1]]
        for cells in (line.split("|") for line in done.stdout.splitlines()[2:])
    }


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


def test_a_portfolio_variant_is_counted_in_the_default_s_place(tmp_path):
    peers = tmp_path / "peers.json"
    peers.write_text(
        json.dumps(
            {
                "runs": [
                    run("portfolio", "a", ["x"]),
                    run("portfolio", "b", ["x", "y"]),
                    run("cem", "a", ["x", "y"]),
                    run("cem", "b", ["x"]),
                ]
            }
        )
    )
    variant = {"variant": "wider", "failures": 2}
    variants = tmp_path / "variants.json"
    variants.write_text(
        json.dumps(
            {
                "runs": [
                    variant | {"case": "a", "seed": 0, "classes": ["x", "y", "z"]},
                    variant | {"case": "b", "seed": 0, "classes": ["x"]},
                ]
            }
        )
    )
    table = variants_table(variants, peers, "--seeds", "0")
    # The default: 3 classes, as many as cem (and all of the case's classes) in b only; the
    # variant in its place: 4, one run more (a) and one fewer (b), and in both cases as many
    # classes as cem and every class found there.
    assert table["classes"] == ["3", "4"]
    assert table["runs with more / fewer classes than the default"] == ["", "1 / 1"]
    assert table["failures"] == ["2", "4"]
    assert table["cases with as many classes as every method, per seed"] == ["1", "2"]
    assert table["cases with every method's classes together, per seed"] == ["1", "2"]


def test_portfolio_variants_compare_with_another_variant_and_list_one_case(tmp_path):
    peers = tmp_path / "peers.json"
    peers.write_text(json.dumps({"runs": [run("portfolio", "a", ["x"])]}))
    runs = [
        {"variant": "old", "case": "a", "seed": 0, "classes": ["x", "y"], "failures": 5},
        {"variant": "new", "case": "a", "seed": 0, "classes": ["x"], "failures": 7},
        {"variant": "new", "case": "a", "seed": 1, "classes": ["x"], "failures": 3},
    ]
    runs[0]["first_failure_episode"], runs[1]["first_failure_episode"] = 40, 9
    variants = tmp_path / "variants.json"
    variants.write_text(json.dumps({"runs": runs}))
    # Against "old" (two classes), the default and "new" (one each) have one run with fewer.
    compared = variants_table(variants, peers, "--seeds", "0", "--against", "old")
    assert compared["runs with more / fewer classes than old"] == ["0 / 1", "0 / 0", "0 / 1"]
    assert compared["median first failure"] == ["-", "40", "9"]
    # One case, seed by seed: failures (classes, first failure), "-" where a seed was not run.
    listed = variants_table(variants, peers, "--case", "a", "--seeds", "0", "1")
    assert listed["old: failures (classes, first failure)"] == ["5 (2, 40)", "-"]
    assert listed["new: failures (classes, first failure)"] == ["7 (1, 9)", "3 (1, -)"]
    # Below the variants, every method of the other files (here the first default).
    assert listed["portfolio: failures (classes, first failure)"] == ["1 (1, -)", "-"]


def test_portfolio_variants_sum_what_each_arm_played_and_found_first(tmp_path):
    peers = tmp_path / "peers.json"
    peers.write_text(json.dumps({"runs": [run("portfolio", "a", ["x"])]}))

    def arms(first_found: dict[str, int], episodes: int) -> dict[str, object]:
        return {
            "aimed": {"episodes": episodes, "failures": 3, "classes_first_found": first_found},
            "random": {"episodes": 100, "failures": 0, "classes_first_found": {}},
        }

    runs = [
        {"variant": "v", "case": "a", "seed": 0, "arms": arms({"x": 5, "other": 9}, 400)},
        {"variant": "v", "case": "b", "seed": 0, "arms": arms({"y": 350, "z": 20}, 600)},
        {"variant": "v", "case": "a", "seed": 5, "arms": arms({"w": 700}, 900)},
    ]
    variants = tmp_path / "variants.json"
    variants.write_text(json.dumps({"runs": runs}))
    rows = variants_table(variants, peers, "--arms", "v")
    # Seeds 0-2 only (the seed-5 run is left out); "other" is no class; y came late (>= 300).
    assert rows["aimed"] == ["1,000", "6", "3", "1", "3.0"]
    assert rows["random"] == ["200", "0", "0", "0", "0.0"]
    argv = [sys.executable, str(VARIANTS), str(variants), str(peers), "--arms", "w"]
    missing = subprocess.run(argv, capture_output=True, text=True, timeout=60, check=False)
    assert missing.returncode != 0
    assert "no variant 'w'" in missing.stderr
    # Nor does an unknown variant to compare against print half a table first.
    argv[-2:] = ["--against", "w"]
    missing = subprocess.run(argv, capture_output=True, text=True, timeout=60, check=False)
    assert missing.returncode != 0
    assert missing.stdout == ""
    assert "--against: no variant 'w'" in missing.stderr
