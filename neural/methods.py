"""How a material is evaluated (SPEC section 8): the one list of methods, and the
word enums every mode of the project is written with.

A light module (no torch) at the bottom of the package plan, so the command
line, the previewer, the Mitsuba plugin and the BRDF factory
(``training.brdfs.brdf_for``) share it without importing each other.
"""
from __future__ import annotations

from enum import Enum


class WordEnum(str, Enum):
    """An enum whose value is its command-line and file word."""

    @classmethod
    def words(cls) -> tuple[str, ...]:
        """The words, in order."""
        return tuple(m.value for m in cls)

    @classmethod
    def parse(cls, word, place: str = "mode"):
        """The member named by ``word``; a clear one-line error otherwise."""
        if isinstance(word, cls):
            return word
        try:
            return cls(str(word))
        except ValueError:
            raise ValueError(f"{place}: {word!r} is not one of {', '.join(cls.words())}") from None

    def __str__(self) -> str:  # argparse prints choices with str()
        return self.value


class CodedWordEnum(WordEnum):
    """A word enum whose position is also an integer code (what a shader compares against)."""

    @property
    def code(self) -> int:
        """The integer the shaders receive for this member (its position)."""
        return list(type(self)).index(self)


class Method(WordEnum):
    """How ``nbrdf eval`` / ``nbrdf lobe``, the reports and the previewer evaluate a material."""
    REFERENCE = "reference"  #: ground truth: closed form or Monte Carlo
    NEURAL = "neural"        #: the full neural path the viewer uses
    PROJECTED = "projected"  #: the decoder at a latent fitted to the reference
    REFINED = "refined"      #: the network's code refined against the Monte Carlo walk within a time budget
    CALIBRATED = "calibrated"  #: the network's code with its directional albedo settled to the walk's
    ANALYTIC = "analytic"    #: closed form; the analytic layering approximation for stacks
    BELCOUR = "belcour"      #: Belcour 2018's layered model (statistical operators), a baseline


#: The method words, in order.
METHODS: tuple[str, ...] = Method.words()
