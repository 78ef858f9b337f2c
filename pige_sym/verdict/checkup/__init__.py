"""The regular check-up: a short run that says whether the machine drifted, and when it will leave its tolerance.

- :mod:`~pige_sym.verdict.checkup.limits` control limits per PIGE from the machine's own check-ups (a Shewhart chart,
  Student t, Bonferroni over the PIGEs);
- :mod:`~pige_sym.verdict.checkup.trend` the drift rate (Theil–Sen with Sen's interval) and when a PIGE leaves its
  tolerance, with an interval;
- :mod:`~pige_sym.verdict.checkup.reference` the machine's runs read as a chart: the last full calibration, the held
  PIGEs, segments, points;
- :mod:`~pige_sym.verdict.checkup.to_enter` the changes to enter;
- :mod:`~pige_sym.verdict.checkup.routine` ``pige checkup``: fit, judge, store;
- :mod:`~pige_sym.verdict.checkup.fleet` ``pige history fleet``: every machine's last calibration, last check-up,
  verdict and next due.

The method in words and the measured false-alarm and detection figures: docs/checkup.md.
"""
