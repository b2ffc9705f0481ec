"""The evaluation of policies on the calibration env (``vical-evaluate``, docs/evaluation.md).

``harness``: episodes on sampled sensors, calibrations at path budgets, the table rows;
``error_vs_effort``: errors at each path budget, paired comparisons with a reference, the figure;
``intervals``: bootstrap and binomial confidence intervals; ``results_file``: ``results.csv`` read
back; ``seed_choice``: the rule that picks the training seed to ship; ``yardstick``: the frozen
yardstick's fingerprint.
"""
