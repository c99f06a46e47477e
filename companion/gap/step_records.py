"""What each step of the gap workflow found, as typed records; ``as_dict`` gives the JSON document's
entry (``GapResult.iterations``, ``GapResult.alternatives``), keys in the order the report reads them."""

from __future__ import annotations

from dataclasses import dataclass

from companion.gap import explain, selection
from companion.gap.scoring import Explanation

#: explanations listed per step (the ranking's head; the rest score lower)
LISTED = 8
#: vetoed explanations listed per step
LISTED_VETOED = 4


def _test(x: Explanation, terms0) -> dict:
    """The test behind a step's choice: the corrected likelihood ratio against the explanation's level."""
    return {"effect": x.label(terms0), "lr": x.lr, "lr_raw": x.delta_dev, "inflation": x.inflation,
            "threshold": x.penalty, "score": x.score}


@dataclass
class IterationRecord:
    """One forward step: the ranking from the state, the test of its best explanation, the choice."""

    iteration: int
    gap_base: float
    choice: selection.StepChoice
    #: the explanation the step's test is about (the ranking's best after the rules and the evidence)
    top: Explanation | None
    runner_up: Explanation | None
    chosen: Explanation | None
    terms0: list

    def as_dict(self) -> dict:
        c, terms0 = self.choice, self.terms0
        d = {"iteration": self.iteration, "gap_base": self.gap_base,
             "candidates": [{"effect": x.effect, "delta_dev": x.delta_dev, "k": x.k, "gap": x.fit.gap,
                             "params": {k: v for k, v in x.added_term().items() if k != "effect"}}
                            for x in c.ranked if x.effect and not x.recal],
             "explanations": [x.as_dict(terms0) for x in c.ranked[:LISTED]],
             "threshold": {k: selection.add_penalty(k) for k in (1, 2)},
             "recal_threshold": selection.RECAL_PENALTY}
        if c.vetoed:
            d["vetoed"] = [{"explanation": x.label(terms0), "score": x.score, "reason": r}
                           for x, r in c.vetoed[:LISTED_VETOED]]
        if c.nested:
            d["nested"] = c.nested
        if c.trend:
            d["trend"] = c.trend
        if self.top is not None:
            d["test"] = _test(self.top, terms0)
            d["runner_up"] = self.runner_up.as_dict(terms0) if self.runner_up is not None else None
        d["chosen"] = self.chosen.label(terms0) if self.chosen is not None else None
        if self.chosen is not None:
            d["gap_after"] = self.chosen.fit.gap
        return d


@dataclass
class SwapRecord:
    """A recalibration taken as the rider of another change, weighed again against every effect from the
    state with that term held: the effect that won over it."""

    iteration: int
    #: the recalibrated model term ("random_walk K")
    swap: str
    gap_base: float
    choice: selection.StepChoice
    #: the recalibration's own score, dD - phi x 10.8
    recalibration_score: float
    terms0: list

    def as_dict(self) -> dict:
        c, x, terms0 = self.choice, self.choice.chosen, self.terms0
        d = {"iteration": self.iteration, "swap": self.swap, "gap_base": self.gap_base, "candidates": [],
             "explanations": [y.as_dict(terms0) for y in c.ranked[:LISTED]], "test": _test(x, terms0),
             "recalibration_score": self.recalibration_score, "chosen": x.label(terms0), "gap_after": x.fit.gap,
             "runner_up": c.runner_up.as_dict(terms0) if c.runner_up is not None else None}
        if c.trend:
            d["trend"] = c.trend
        return d


def alternative_entry(iteration: int, chosen: Explanation, runner_up: Explanation | None, terms0) -> dict:
    """A chosen explanation beside its runner-up and the margin between their scores."""
    return {"iteration": iteration, "chosen": chosen.as_dict(terms0),
            "runner_up": runner_up.as_dict(terms0) if runner_up is not None else None,
            "margin": selection.margin(chosen, runner_up) if runner_up is not None else None,
            "text": explain.explain_runner_up(chosen.label(terms0), chosen.score,
                                              runner_up.label(terms0) if runner_up is not None else None,
                                              runner_up.score if runner_up is not None else None)}


def swap_alternative_entry(iteration: int, x: Explanation, mod: str, hold, value: float, terms0) -> dict:
    """The effect ``x`` that won over the recalibration ``mod`` (its hold test ``hold``, score ``value``)."""
    return {"iteration": iteration, "chosen": x.as_dict(terms0),
            "runner_up": {"explanation": f"recalibrated {mod}", "delta_dev": hold.lr_raw,
                          "inflation": hold.inflation, "lr": hold.lr_raw / hold.inflation,
                          "penalty": selection.RECAL_PENALTY, "score": value},
            "margin": x.score - value,
            "text": explain.explain_runner_up(x.label(terms0), x.score, f"recalibrated {mod}", value)}
