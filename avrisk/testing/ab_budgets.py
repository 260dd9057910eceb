"""The settings of the paired comparison's efficiency table.

The paired run (:func:`avrisk.rare.paired.paired_splitting_is`) against two
independent single-version ``splitting_is`` runs, one per version, at about
the same evaluations of the versions: each draw of a paired run is evaluated
by both, so a paired run at ``N`` samples costs what two single runs at
``N`` samples each cost. ``benchmarks/ab_coverage.py`` (analytic pairs) and
``benchmarks/ab_scenario.py`` (the bundled pair) compare at these settings.
Both sides search as the paired run does, without the refresh at ``gamma``
(``PAIRED_DEFAULTS``), so that what differs is the pairing alone.
"""

from __future__ import annotations

from avrisk.rare.paired import PAIRED_DEFAULTS
from avrisk.rare.splitting_is_settings import SplittingISSettings

__all__ = ["EVEN", "INDEPENDENT", "PAIRED", "SINGLE"]

_SAMPLES = ("n_particles", "n_final")
_SEARCH = {"refresh_rounds": PAIRED_DEFAULTS["refresh_rounds"]}

#: The paired run: ``avrisk ab``'s defaults.
PAIRED: dict[str, int] = dict(PAIRED_DEFAULTS)
#: A single-version run at ``avrisk run``'s default samples: two of them make
#: about as many evaluations as the default paired run.
SINGLE: dict[str, int] = {
    **{name: SplittingISSettings.model_fields[name].default for name in _SAMPLES},
    **_SEARCH,
}
#: Each independent run at half ``SINGLE``'s samples.
INDEPENDENT: dict[str, int] = {
    **{name: SINGLE[name] // 2 for name in _SAMPLES},
    **_SEARCH,
}
#: The paired run at half the default's samples: about as many evaluations as
#: the two ``INDEPENDENT`` runs together.
EVEN: dict[str, int] = {
    **{name: PAIRED_DEFAULTS[name] // 2 for name in _SAMPLES},
    **_SEARCH,
}
