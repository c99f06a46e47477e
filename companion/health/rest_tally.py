"""What the stuck detector learns from still blocks at rest about a healthy axis' codes and level: running sums
kept apart while a run of codes is judged and added in once the run ends healthy (numpy-free dataclasses; their
lists are the run state file's format).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass
class CodeTally:
    """Still blocks' samples: how often they leave two adjacent codes, and their spread in value."""

    outside: int = 0  # samples beyond the two adjacent codes that hold the most of their block
    samples: int = 0  # samples counted for ``outside``
    var_sum: float = 0.0  # sum over blocks of the block's sample variance (ddof 1) times its samples
    var_samples: int = 0  # samples in ``var_sum``
    dd_sq: float = 0.0  # sum of squared second differences
    dd_count: int = 0  # second differences in ``dd_sq``

    def add(self, other: "CodeTally") -> None:
        self.outside += int(other.outside)
        self.samples += int(other.samples)
        self.var_sum += other.var_sum
        self.var_samples += int(other.var_samples)
        self.dd_sq += other.dd_sq
        self.dd_count += int(other.dd_count)

    @property
    def spread(self) -> list:
        """[var_sum, var_samples, dd_sq, dd_count] (the state file's ``spread``)."""
        return [self.var_sum, self.var_samples, self.dd_sq, self.dd_count]

    def to_list(self) -> list:
        return [self.outside, self.samples] + self.spread

    @classmethod
    def from_lists(cls, out, spread) -> "CodeTally":
        """From the state file's ``out`` [outside, samples] and ``spread`` (missing entries 0)."""
        o = [int(v) for v in (out or [0, 0])]
        sp = list(spread or []) + [0.0, 0, 0.0, 0][len(spread or []):]
        return cls(o[0], o[1], float(sp[0]), int(sp[1]), float(sp[2]), int(sp[3]))

    @classmethod
    def from_list(cls, values) -> "CodeTally":
        """From the state file's ``pend`` (missing entries 0)."""
        pd = list(values or []) + [0, 0, 0.0, 0, 0.0, 0][len(values or []):]
        return cls(int(pd[0]), int(pd[1]), float(pd[2]), int(pd[3]), float(pd[4]), int(pd[5]))


@dataclass
class JitterTally:
    """Pairs of successive still blocks: how far a healthy level moves from one block to the next (LSB)."""

    d2: float = 0.0  # sum of their means' squared differences (each clipped at 1 LSB^2)
    within: float = 0.0  # sum of the share of those their samples' own noise explains
    pairs: int = 0

    def add(self, other: "JitterTally") -> None:
        self.d2 += other.d2
        self.within += other.within
        self.pairs += other.pairs

    def to_list(self) -> list:
        return [self.d2, self.within, self.pairs]

    @classmethod
    def from_list(cls, values) -> "JitterTally":
        v = values or [0.0, 0.0, 0]
        return cls(float(v[0]), float(v[1]), int(v[2]))


@dataclass
class LeadErrors:
    """Squared errors (LSB^2, each clipped at 1) of the expected healthy level 1 block and ``lead`` blocks ahead."""

    sq1: float = 0.0
    n1: int = 0
    sq_lead: float = 0.0
    n_lead: int = 0

    def to_list(self) -> list:
        return [self.sq1, self.n1, self.sq_lead, self.n_lead]

    @classmethod
    def from_list(cls, values) -> "LeadErrors":
        v = values or [0.0, 0, 0.0, 0]
        return cls(float(v[0]), int(v[1]), float(v[2]), int(v[3]))
