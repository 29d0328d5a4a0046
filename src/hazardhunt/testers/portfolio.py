"""The default tester: a portfolio of samplers that moves its budget to what finds new failures.

Which search finds the most distinct failures differs from one system under test to the next:
a human aimed at the robot finds the failures that need someone who comes for it, the plain
attacks and the walks to the robot's route find the bugs in a controller's logic, uniform
sampling the failures that are everywhere. A safety engineer does not know beforehand which
kind their system has. The portfolio runs them all as arms and, as it runs, gives more of the
budget to the arms that keep finding something new (as Nevergrad's NGOpt or Optuna's automatic
sampler choose an optimiser, but judged on distinct failure mechanisms rather than on a best
score). Its default arms (:data:`DEFAULT_ARMS`), in the order of their first look:

- ``cem-aim``: the cross-entropy method aimed at the robot, walking round obstacles;
- ``cem-mixed``: the cross-entropy method over every decision space in turn, walking round
  obstacles, starting from the plain attacks;
- ``cem-ambush``: the cross-entropy method over humans who wait beside the robot's route and
  run at its side as it passes, walking round obstacles, starting from the plain ambushes;
- ``qd-mixed``: quality-diversity search over every decision space, one emitter each;
- ``random``: uniform random sampling of open-loop actions that keep off walls and shelves;
- ``mirror``: for a failure any arm found, the same episode mirrored left for right, while the
  robot's other side has no failure of its kind: one episode per side checked;
- ``boundary``: for a failure any arm found, bisection towards a nearby episode that did not
  fail (:mod:`hazardhunt.testers.boundary`): where a failure region ends its mechanism often
  changes first (a human the field saw too late rather than never); once it has failures to
  follow it plays at least a fifth of the run's episodes (``min_share``), as the bands it looks
  for are thin.

How the budget moves:

- first every arm takes its first look, back to back in the arms' order: one batch per decision
  space it searches in turn (the plain attacks of ``cem-mixed`` among them);
- an episode's gain is ``class_gain`` = 1 for a failure of a class no arm has found before
  (the built-in taxonomy, :class:`~hazardhunt.spec.failure_classes.MechanismClassifier`),
  ``cell_gain`` = 0.3 for one in a new cell of the failure descriptors (sector of the robot,
  safety-layer history, human moving or standing), and ``repeat_gain`` = 0.03 for any other
  failure; until the run's first failure, ``closer_gain`` = 0.1 for an episode that came closer
  to one than every episode before it (the objective's score), gains forgotten at the first
  failure;
- each arm's value is its gain per episode, discounted so that what it found lately counts
  most, plus a bonus for arms tried less (discounted UCB; Garivier and Moulines 2011), and the
  next batch goes to the arm of highest value;
- an arm with a ``min_share`` plays at least that share of the run's episodes whenever it has
  one to propose;
- every arm keeps at least ``floor`` / (number of arms) of the episodes played, so that a
  search that finds its first failure late (behind a protective field) gets to find it; the
  mirror and the boundary propose nothing before the first failure, and the mirror, which
  plays few episodes, is asked first whenever it has one to play.

Searching on a requirement (``hazardhunt run --search-on NAME``), a violation counts as a
failure does here, its class the requirement's name and the signals that explain it
(``slow-near-people/clearance+robot_speed``).

The failures found count as known for every arm: the cross-entropy arms score a failure by its
distance from all failures the portfolio has, so each arm is pushed away from what the others
found. An arm with ``observe`` (:class:`~hazardhunt.testers.search.Observer`; the mirror
and the boundary) hears every batch the others play. An arm that raises is dropped, with a
warning in the run's record, and the others share its budget. The run records which arm
played each episode (``tester/arms.csv``), what each arm found (``tester/portfolio.json``)
and the quality-diversity arm's archive (``tester/archive.parquet``).
"""

from __future__ import annotations

import math
import os
import warnings
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator

from hazardhunt.sim.simulation import EpisodeResult, UnusableActionError
from hazardhunt.spec.failure_classes import MechanismClassifier
from hazardhunt.sut.guard import is_plugin_fault
from hazardhunt.sut.plugins import PluginError, build
from hazardhunt.testers.base import Tester, TesterParameterError
from hazardhunt.testers.boundary import BoundaryParams, BoundarySampler
from hazardhunt.testers.cem import CrossEntropyParams, CrossEntropySampler
from hazardhunt.testers.evaluator import Plan, unusable_decisions
from hazardhunt.testers.mirror import MirrorParams, MirrorSampler, failure_cell
from hazardhunt.testers.novelty import FailureArchive
from hazardhunt.testers.objective import ContactRule, violation_class
from hazardhunt.testers.qd import QualityDiversityParams, QualityDiversitySampler
from hazardhunt.testers.random_sampling import UniformParams, UniformSampler
from hazardhunt.testers.search import (
    Observer,
    Sampler,
    SearchContext,
    SearchParams,
    SearchTester,
    parse_params,
)
from hazardhunt.testers.spaces import SearchSpace

METHODS: dict[str, type[SearchParams]] = {
    "mirror": MirrorParams,
    "boundary": BoundaryParams,
    "uniform": UniformParams,
    "cem": CrossEntropyParams,
    "qd": QualityDiversityParams,
}
"""The samplers an arm may use, by name, with their settings."""


class Arm(BaseModel):
    """One sampler of the portfolio and its settings."""

    model_config = ConfigDict(extra="forbid", frozen=True, strict=True)

    name: str = Field(min_length=1)
    """How the run's record names the arm."""
    method: str
    """``cem``, ``qd``, ``uniform``, ``mirror``, ``boundary``, or a sampler of one's own: the
    import path (``package.module:Class``) of a :class:`~hazardhunt.testers.search.SearchTester`,
    called as ``Class(seed=..., **params)``, whose ``make_sampler`` makes the arm's sampler."""
    params: dict[str, Any] = {}
    """The sampler's settings (those of ``hazardhunt run --tester METHOD``, but ``workers``,
    which the portfolio sets)."""
    min_share: float = Field(default=0.0, ge=0.0, le=1.0, allow_inf_nan=False)
    """The least share of the run's episodes the arm plays whenever it has an episode to
    propose, whatever it finds (for an arm that needs many episodes to reach a thin band of
    failures, like the boundary's bisection lines). 0: only the portfolio's ``floor``."""

    @field_validator("method")
    @classmethod
    def _known(cls, method: str) -> str:
        if method not in METHODS and ":" not in method:
            raise ValueError(
                f"must be one of {', '.join(METHODS)} or the import path of your own "
                "(package.module:Class)"
            )
        return method


DEFAULT_ARMS = (
    Arm(name="cem-aim", method="cem", params={"space": {"kind": "aim", "detour": True}}),
    Arm(
        name="cem-mixed",
        method="cem",
        params={"space": {"kind": "mixed", "detour": True, "plain_attacks": True}},
    ),
    Arm(
        name="cem-ambush",
        method="cem",
        params={"space": {"kind": "ambush", "detour": True, "plain_attacks": True}},
    ),
    Arm(
        name="qd-mixed",
        method="qd",
        params={"emitters": 3, "space": {"kind": "mixed", "detour": True}},
    ),
    Arm(name="random", method="uniform", params={"space": {"kind": "open", "detour": True}}),
    Arm(name="mirror", method="mirror"),
    Arm(name="boundary", method="boundary", min_share=0.2),
)
"""The arms of the default portfolio, in the order of their first look: the configurations that
were each the best on some kind of system under test (docs/search-methods.md). The aimed arm
plays the run's first batch, as behind a protective field a human who comes for the robot finds
the first failure soonest; ``cem-mixed``'s plain attacks follow within the first 80 episodes.
The first default had six arms, ``cem-mixed`` first, no ``cem-ambush`` and no ``min_share`` for
the boundary (:data:`FIRST_DEFAULT_ARMS`)."""
_DEFAULT_BY_NAME = {arm.name: arm for arm in DEFAULT_ARMS}
FIRST_DEFAULT_ARMS = tuple(
    _DEFAULT_BY_NAME[name].model_copy(update={"min_share": 0.0})
    for name in ("cem-mixed", "cem-aim", "qd-mixed", "random", "mirror", "boundary")
)
"""The six arms of the first default, in its order, with which the results published before the
``cem-ambush`` arm were measured (``campaigns/study-portfolio.toml`` names them)."""


class PortfolioParams(SearchParams):
    """The portfolio's settings."""

    arms: tuple[Arm, ...] = Field(default=DEFAULT_ARMS, min_length=1)
    """The samplers the budget is shared between."""
    floor: float = Field(default=0.3, ge=0.0, le=1.0, allow_inf_nan=False)
    """The share of the episodes spread evenly over the arms whatever they find."""
    discount: float = Field(default=0.9, gt=0.0, le=1.0, allow_inf_nan=False)
    """Weight of an arm's earlier batches against its latest, per batch the portfolio plays."""
    optimism: float = Field(default=0.02, ge=0.0, allow_inf_nan=False)
    """Scale of the bonus for arms tried less (in gain per episode)."""
    class_gain: float = Field(default=1.0, ge=0.0, le=1.0, allow_inf_nan=False)
    """An episode's gain for a failure of a class no arm has found."""
    cell_gain: float = Field(default=0.3, ge=0.0, le=1.0, allow_inf_nan=False)
    """An episode's gain for a failure in a descriptor cell no arm has filled (the larger of
    the two when it is of a new class too)."""
    repeat_gain: float = Field(default=0.03, ge=0.0, le=1.0, allow_inf_nan=False)
    """An episode's gain for any other failure."""
    closer_gain: float = Field(default=0.1, ge=0.0, le=1.0, allow_inf_nan=False)
    """Before the run's first failure, an episode's gain for coming closer to one (the search
    objective's score: the largest risk, or the requirement's robustness) than every episode
    before it (0: the budget moves only on what the failures found)."""

    @field_validator("arms", mode="before")
    @classmethod
    def _arm_tables(cls, arms: Any) -> Any:
        return tuple(arms) if isinstance(arms, list) else arms

    @field_validator("arms")
    @classmethod
    def _distinct(cls, arms: tuple[Arm, ...]) -> tuple[Arm, ...]:
        names = [arm.name for arm in arms]
        if len(set(names)) != len(names):
            raise ValueError(f"arm names must differ: {', '.join(names)}")
        if sum(arm.min_share for arm in arms) > 1.0:
            raise ValueError("the arms' min_share add up to more than 1")
        for arm in arms:
            if "workers" in arm.params:
                raise ValueError(f"arm {arm.name!r}: workers is the portfolio's setting")
            try:
                if arm.method in METHODS:
                    parse_params(arm.name, METHODS[arm.method], arm.params)
                else:
                    own_tester(arm, seed=0)
            except TesterParameterError as error:
                raise ValueError(f"arm {arm.name!r}: {error.key}: {error.problem}") from None
            except PluginError as error:
                raise ValueError(f"arm {arm.name!r}: {error}") from None
        return arms


@dataclass
class _ArmState:
    """One arm as the portfolio runs it."""

    arm: Arm
    sampler: Sampler
    episodes: int = 0
    failures: int = 0
    classes: dict[str, int] = field(default_factory=dict)
    """The classes this arm found first, with the episode it found each in."""
    weighted_gain: float = 0.0
    weighted_closer: float = 0.0
    """Gain for coming closer to a failure, earned before the run's first; 0 from then on."""
    weighted_episodes: float = 0.0
    dropped: str | None = None
    """Why the arm was taken out of the portfolio (it raised), if it was."""
    batches: int = 0
    first_look: int = 1
    """Batches the arm plays back to back before the budget moves by what it finds: one per
    decision space it searches, so that it has tried each (its plain attacks, say)."""

    def value(self, total: float, optimism: float) -> float:
        if self.weighted_episodes <= 0.0:
            return math.inf
        mean = (self.weighted_gain + self.weighted_closer) / self.weighted_episodes
        return mean + optimism * math.sqrt(max(math.log(total), 0.0) / self.weighted_episodes)


class PortfolioSampler:
    """Asks the arm of highest value for its next batch; credits it with what it found."""

    def __init__(self, params: PortfolioParams, context: SearchContext) -> None:
        self.params = params
        known = FailureArchive(neighbours=1)
        self.arms = [
            _ArmState(arm, _sampler(arm, _arm_context(context, arm), known), first_look=_looks(arm))
            for arm in params.arms
        ]
        self.objective = context.objective
        self.classifier = MechanismClassifier(robot=context.simulation.robot_params)
        self.field = context.simulation.field
        self.classes_found: set[str] = set()
        self.cells_found: set[tuple[int, ...]] = set()
        self.episode_arms: list[str] = []
        self.closest = -math.inf
        self._asking: _ArmState | None = None

    def ask(self) -> list[Plan]:
        idle: set[str] = set()  # arms with nothing to propose now (the mirror, the attacks)
        while True:
            state = self._asking = self._choose(idle)
            try:
                plans = state.sampler.ask()
            except BaseException as error:  # a user's sampler may raise anything, SystemExit too
                if not is_plugin_fault(error):
                    raise
                self._drop(state, error)
                continue
            unusable = next(filter(None, map(unusable_decisions, plans)), None)
            if unusable is not None:
                self._drop(state, UnusableActionError(unusable))
                continue
            if plans:
                return plans
            idle.add(state.arm.name)

    def _choose(self, idle: set[str]) -> _ArmState:
        active = [state for state in self.arms if state.dropped is None]
        if not active:
            problems = "; ".join(f"{state.arm.name}: {state.dropped}" for state in self.arms)
            raise RuntimeError(f"tester 'portfolio': every arm failed ({problems})")
        active = [state for state in active if state.arm.name not in idle]
        if not active:
            raise RuntimeError("tester 'portfolio': no arm has an episode to propose")
        for state in active:  # in the arms' order
            if state.batches < state.first_look:
                return state
        for state in active:
            if state.episodes < state.arm.min_share * len(self.episode_arms):
                return state
        played = sum(state.episodes for state in active)
        least = min(active, key=lambda state: state.episodes)
        if least.episodes == 0 or least.episodes < self.params.floor * played / len(active):
            return least
        total = sum(state.weighted_episodes for state in active)
        return max(active, key=lambda state: state.value(total, self.params.optimism))

    def _drop(self, state: _ArmState, error: BaseException) -> None:
        """Take an arm that raised (or proposed decisions that cannot be played) out of the
        portfolio; the others share its budget."""
        state.dropped = f"{type(error).__name__}: {error}"
        did = error if isinstance(error, UnusableActionError) else "raised"
        warnings.warn(
            f"portfolio arm {state.arm.name!r} {did} and was dropped: {state.dropped}",
            RuntimeWarning,
            stacklevel=2,
        )

    def tell(self, plans: list[Plan], results: list[EpisodeResult]) -> None:
        state = self._asking
        assert state is not None, "tell() before ask()"
        first = len(self.episode_arms)
        failed_before = bool(self.classes_found)
        gain = sum(self._gain(state, result, first + i) for i, result in enumerate(results))
        for other in self.arms:
            other.weighted_gain *= self.params.discount
            other.weighted_closer *= self.params.discount
            other.weighted_episodes *= self.params.discount
        state.weighted_gain += gain
        if not self.classes_found:
            state.weighted_closer += self.params.closer_gain * self._closer(results)
        elif not failed_before:  # the first failure: from now on only failures move the budget
            for other in self.arms:
                other.weighted_closer = 0.0
        state.weighted_episodes += len(results)
        state.episodes += len(results)
        state.batches += 1
        self.episode_arms += [state.arm.name] * len(results)
        self._asking = None
        try:
            state.sampler.tell(plans, results)
        except BaseException as error:  # a user's sampler may raise anything, SystemExit too
            if not is_plugin_fault(error):
                raise
            self._drop(state, error)
        for other in self.arms:
            if other is state or other.dropped or not isinstance(other.sampler, Observer):
                continue
            try:
                other.sampler.observe(plans, results)
            except BaseException as error:  # a user's sampler may raise anything
                if not is_plugin_fault(error):
                    raise
                self._drop(other, error)

    def _gain(self, state: _ArmState, result: EpisodeResult, episode: int) -> float:
        """What ``episode``, played by ``state``'s arm, found that no arm had."""
        summary = result.summary
        if not self.objective.hit(result):
            return 0.0
        state.failures += 1
        gain = self.params.repeat_gain
        failure_class = (
            self.classifier.classify(result.trajectory or (), summary, self.field)
            if isinstance(self.objective, ContactRule)
            else violation_class(self.objective.name, result)
        )
        if failure_class not in self.classes_found:
            self.classes_found.add(failure_class)
            state.classes[failure_class] = episode
            gain = self.params.class_gain
        cell = failure_cell(summary, self.classifier.moving_speed)
        if cell not in self.cells_found:
            self.cells_found.add(cell)
            gain = max(gain, self.params.cell_gain)
        return gain

    def _closer(self, results: list[EpisodeResult]) -> int:
        """How many of ``results``, in order, came closer to a failure than every episode
        before them (the objective's score)."""
        closer = 0
        for result in results:
            score = self.objective.score(result)
            if score > self.closest:
                self.closest = score
                closer += 1
        return closer

    def record(self) -> dict[str, Any]:
        return {
            "arms_played": {
                state.arm.name: {
                    "episodes": state.episodes,
                    "failures": state.failures,
                    "classes_first_found": state.classes,
                    "dropped": state.dropped,
                    **state.sampler.record(),
                }
                for state in self.arms
            }
        }


def _looks(arm: Arm) -> int:
    """The batches of an arm's first look: one per decision space it searches in turn (one for
    quality-diversity, whose every batch spans them, after its plain attacks; none for the
    mirror and the boundary, which wait for failures)."""
    if arm.method not in METHODS:
        return 1
    params = parse_params(arm.name, METHODS[arm.method], arm.params)
    if isinstance(params, MirrorParams | BoundaryParams):
        return 0
    if isinstance(params, QualityDiversityParams):  # each batch spans every space
        attacks = params.space.plain_attacks
        return 1 + (len(params.space.decision_spaces) if attacks else 0)
    space = getattr(params, "space", None)
    return len(space.decision_spaces) if isinstance(space, SearchSpace) else 1


def _arm_context(context: SearchContext, arm: Arm) -> SearchContext:
    """The run's context with the arm's own seed, drawn from the run's seed and the arm's name
    (so that adding an arm leaves the others' episodes as they were)."""
    entropy = [context.seed, zlib.crc32(arm.name.encode())]
    seed = int(np.random.SeedSequence(entropy).generate_state(1)[0])
    return SearchContext(context.simulation, seed, context.objective)


def own_tester(arm: Arm, seed: int) -> SearchTester:
    """The search tester of an arm whose method is an import path, built with its parameters;
    its module is found on the Python path or in the working directory.

    Raises:
        PluginError: It does not load, does not take the parameters, or makes no sampler.
    """
    tester = build("portfolio arm", arm.method, {"seed": seed, **arm.params}, Tester, [os.getcwd()])
    if not callable(getattr(tester, "make_sampler", None)):
        raise PluginError(
            f"{arm.method!r} has no make_sampler(context): an arm is a SearchTester "
            "(hazardhunt.testers.search)"
        )
    return cast(SearchTester, tester)


def _sampler(arm: Arm, context: SearchContext, known: FailureArchive) -> Sampler:
    if arm.method not in METHODS:
        return own_tester(arm, context.seed).make_sampler(context)
    params = parse_params(arm.name, METHODS[arm.method], arm.params)
    if isinstance(params, CrossEntropyParams):
        return CrossEntropySampler(params, context, known)
    if isinstance(params, QualityDiversityParams):
        return QualityDiversitySampler(params, context)
    if isinstance(params, MirrorParams):
        return MirrorSampler(params, context)
    if isinstance(params, BoundaryParams):
        return BoundarySampler(params, context)
    assert isinstance(params, UniformParams)
    return UniformSampler(params, context)


class PortfolioTester(SearchTester):
    """The default tester: uniform sampling, the cross-entropy method and quality-diversity
    search as arms, the budget going to the arms that find new failure mechanisms."""

    name = "portfolio"
    params_model = PortfolioParams
    params: PortfolioParams
    sampler: PortfolioSampler | None

    def make_sampler(self, context: SearchContext) -> PortfolioSampler:
        return PortfolioSampler(self.params, context)

    def save(self, directory: Path) -> None:
        """The settings and what each arm found (``portfolio.json``), which arm played each
        episode (``arms.csv``), and the archive of the first quality-diversity arm
        (``archive.parquet``, which the report draws)."""
        super().save(directory)
        if self.sampler is None:
            return
        arms = self.sampler.episode_arms
        lines = ["episode,arm", *(f"{episode},{arm}" for episode, arm in enumerate(arms))]
        (directory / "arms.csv").write_text("\n".join(lines) + "\n")
        for state in self.sampler.arms:
            if isinstance(state.sampler, QualityDiversitySampler) and state.episodes:
                state.sampler.archive_table().to_parquet(directory / "archive.parquet", index=False)
                break
