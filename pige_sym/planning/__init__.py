"""Plan the R-test before running it (``pige plan``): predicted precision, search, reveal rules.

- :mod:`~pige_sym.planning.prediction`: design, predicted covariance, criteria and gradients;
- :mod:`~pige_sym.planning.families`: limits, trajectory families, structure for effects;
- :mod:`~pige_sym.planning.reveal`: which catalogue effects a test can reveal;
- :mod:`~pige_sym.planning.plan`: the request and the plan (poses, schedule, angle file);
- :mod:`~pige_sym.planning.search`: the search and grading.
"""

from pige_sym.planning.families import Limits, parse_limits
from pige_sym.planning.plan import Plan, PlanRequest
from pige_sym.planning.prediction import CRITERIA, Prediction, Setup, predict
from pige_sym.planning.reveal import RevealStatus, parse_reveal, reveal_report
from pige_sym.planning.search import grade_test, plan_test, search_ball_region

__all__ = ["CRITERIA", "Limits", "Plan", "PlanRequest", "Prediction", "RevealStatus", "Setup", "grade_test",
           "parse_limits", "parse_reveal", "plan_test", "predict", "reveal_report", "search_ball_region"]
