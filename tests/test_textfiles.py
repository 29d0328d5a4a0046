"""A value a file's schema refuses is one line in the file's own words."""

import pytest
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from hazardhunt.textfiles import format_validation_error


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
