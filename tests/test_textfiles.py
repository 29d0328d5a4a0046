"""A value a file's schema refuses is one line in the file's own words."""

import pytest
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from hazardhunt.textfiles import (
    MAX_INPUT_CHARACTERS,
    MAX_LINE_CHARACTERS,
    format_validation_error,
)
from tests.helpers import hazardhunt


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True)


class Start(_Strict):
    x: float
    heading_deg: float = 0.0


class Robot(_Strict):
    start: Start
    speed: float = Field(default=1.0, gt=0)


class Scenario(_Strict):
    robot: Robot | None = None
    seeds: list[int] = Field(default=[0], min_length=1)
    episodes: int = 1
    label: str = ""
    on: bool = False
    kind: str = Field(default="", alias="class")


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"episods": 3}, "episods: unknown key (did you mean episodes?)"),
        ({"seeds": [], "episods": 3},
         "episods: unknown key (did you mean episodes?) (and 1 more problem)"),
        ({"robot": {"start": {"x": 1.0, "headng_deg": 9.0}}},
         "robot.start.headng_deg: unknown key (did you mean heading_deg?)"),
        ({"robot": {"start": {"x": 1.0}, "colour": "red"}}, "robot.colour: unknown key"),
        ({"robot": {"start": {}}}, "robot.start.x: missing"),
        ({"episodes": "2"}, 'episodes: must be a whole number, not "2"'),
        ({"episodes": True}, "episodes: must be a whole number, not true"),
        ({"seeds": [0.5]}, "seeds.0: must be a whole number, not 0.5"),
        ({"seeds": []}, "seeds: must not be empty"),
        ({"seeds": "0"}, 'seeds: must be a list, not "0"'),
        ({"label": ["a", 1, True]}, 'label: must be text, not ["a", 1, true]'),
        ({"clas": 1}, "clas: unknown key (did you mean class?)"),
        ({"robot": 3}, "robot: must be a table, not 3"),
        ({"label": {"a": 1}}, "label: must be text, not a table"),
        ({"on": "yes"}, 'on: must be true or false, not "yes"'),
        ({"robot": {"start": {"x": 1.0}, "speed": 0.0}}, "robot.speed: must be greater than 0"),
        ({"episodes": "y" * 80}, 'episodes: must be a whole number, not "' + "y" * 36 + "..."),
        ({"episodes": "2", "on": "yes"},
         'episodes: must be a whole number, not "2" (and 1 more problem)'),
    ],
)  # fmt: skip
def test_a_refused_value_is_named_with_its_key_in_toml_words(data, message):
    with pytest.raises(ValidationError) as caught:
        Scenario.model_validate(data)
    assert format_validation_error(caught.value, Scenario) == message


def test_without_the_schema_an_unknown_key_is_named_without_a_guess():
    with pytest.raises(ValidationError) as caught:
        Scenario.model_validate({"episods": 3})
    assert format_validation_error(caught.value) == "episods: unknown key"


@pytest.mark.parametrize(
    ("command", "says"),
    [
        (["campaign", "{file}", "--out", "{out}"], "{file}: cannot be read: "),
        (["run", "--scenario", "{file}", "--out", "{out}"], "scenario: {file}: cannot be read: "),
        (
            ["run", "--requirement", "{file}", "--out", "{out}"],
            "requirements: {file}: cannot be read: ",
        ),
        (
            ["estimate", "--people", "{file}", "--episodes", "100", "--out", "{out}"],
            "{file}: cannot read the model of people: ",
        ),
        (
            ["estimate", "--uncertainties", "{file}", "--episodes", "100", "--out", "{out}"],
            "{file}: cannot read the model of the uncertainties: ",
        ),
    ],
    ids=["campaign", "scenario", "requirements", "people", "uncertainties"],
)
def test_an_input_file_larger_than_any_input_needs_is_one_line_before_it_is_read(
    tmp_path, command, says
):
    file, out = tmp_path / "huge.toml", tmp_path / "out"
    file.write_text("#" + " " * MAX_INPUT_CHARACTERS + "\n")  # parsing it is not what is slow
    done = hazardhunt(*(part.format(file=file, out=out) for part in command))
    assert done.returncode == 2
    expected = "larger than 1,000,000 characters, the most hazardhunt reads from one input file"
    assert done.stderr.strip().splitlines() == [f"error: {says.format(file=file)}{expected}"]
    assert not out.exists()


def test_an_error_line_echoes_a_value_from_a_file_cut_short(tmp_path):
    campaign = tmp_path / "campaign.toml"
    name = "x" * 900_000
    campaign.write_text(
        f'scenarios = ["crossing"]\nfields = ["none"]\ntesters = ["{name}"]\nseeds = [0]\n'
        "episodes = 2\n"
    )
    done = hazardhunt("campaign", campaign, "--out", tmp_path / "out")
    assert done.returncode == 2
    [line] = done.stderr.strip().splitlines()
    assert line.startswith(f"error: {campaign}: testers.0: unknown tester 'xxx")
    assert len(line) < MAX_LINE_CHARACTERS + 100
    assert line.endswith(" more characters)")
