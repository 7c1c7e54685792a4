"""
Your own ratings: a wisdom-of-micro-crowds study
================================================

A user collected ratings of some tasks on a 1-10 scale in a CSV with columns ``worker,task,label``
(and, for scoring, the true values in ``task,truth``). ``simfab crowd aggregate`` computes the
classical aggregates and the Bayesian model's, with R-hat and effective sample sizes::

    simfab crowd aggregate ratings.csv --scale 1 10 --truth truth.csv --out my_study
"""

# %%
# A small synthetic crowd: 12 raters of 8 tasks, each rater with their own bias and noise.
import csv

import numpy as np
from _common import show_png, simfab, workdir

d = workdir("crowd")
rng = np.random.default_rng(0)
truth = rng.uniform(2.0, 9.0, size=8)
with open(d / "ratings.csv", "w", newline="") as f:
    w = csv.writer(f)
    w.writerow(["worker", "task", "label"])
    for r in range(12):
        bias, noise = rng.normal(0, 0.7), rng.uniform(0.3, 2.0)
        for t in range(8):
            w.writerow([f"w{r:02d}", f"t{t}", int(np.clip(np.rint(truth[t] + bias + rng.normal(0, noise)), 1, 10))])
with open(d / "truth.csv", "w", newline="") as f:
    w = csv.writer(f)
    w.writerow(["task", "truth"])
    for t in range(8):
        w.writerow([f"t{t}", round(float(truth[t]), 3)])

res = simfab("crowd", "aggregate", d / "ratings.csv", "--scale", "1", "10", "--truth", d / "truth.csv",
             "--chains", "2", "--burn-in", "300", "--draws", "300", "--out", d / "out")
print((d / "out" / "aggregates.csv").read_text().splitlines()[:4])
show_png(d / "out" / "errors_per_question.png")
