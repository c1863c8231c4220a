"""Post-hoc pairwise comparisons after a split-plot ANOVA, as emmeans does them on afex's models.

Every effect (main or interaction; within, between or mixed) gets all pairwise comparisons of its cell
means under one of three follow-ups and one of four adjustments:

* ``followup="univariate"`` (default) — emmeans on afex's ``aov`` model: a pair inside one between group
  uses the within-subject error of the strata it touches; a pair across groups pools in the
  between-subjects error, with Satterthwaite df (the textbook split-plot rule).
* ``followup="multivariate"`` — emmeans on afex's multivariate (``mlm``) model: unstructured covariance,
  df = subjects − groups.
* ``followup="statistica"`` — every pair against the effect's own error term (the paper's tables and
  Statistica); pairs across between groups of a mixed effect are not protected in that convention.
* ``adjust``: ``tukey`` (Tukey–Kramer with each pair's df), ``holm``, ``bonferroni``, ``none``.
* ``means``: ``emmeans`` (equal weights over groups; default for univariate/multivariate) or ``observed``
  (n-weighted; default for statistica).

Modules: :mod:`.means` (cell weights), :mod:`.univariate` and :mod:`.multivariate` (SE and df),
:mod:`.adjust` (p and confidence limits), :mod:`.pairs` (the compiled, vectorised plan),
:mod:`.summary` (labels, ``"L2b > H2b"`` strings), :mod:`.api` (``posthoc``, ``tukey``, ``tukey_all``).
"""

from analysis.posthoc.adjust import ADJUSTMENTS
from analysis.posthoc.api import PosthocResult, posthoc, tukey, tukey_all
from analysis.posthoc.means import MEANS_TYPES
from analysis.posthoc.pairs import FOLLOWUPS, PairPlan, plan_pairs
from analysis.posthoc.summary import abbreviate, summarize

__all__ = ["ADJUSTMENTS", "FOLLOWUPS", "MEANS_TYPES", "PairPlan", "PosthocResult", "abbreviate", "plan_pairs",
           "posthoc", "summarize", "tukey", "tukey_all"]
