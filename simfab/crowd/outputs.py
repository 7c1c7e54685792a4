"""Output files of the crowd pipelines (tables, summaries, figures), shared by the command line
and :mod:`simfab.crowd.survey`. Every writer is atomic (:mod:`simfab.io.atomic`); names taken from
input files (crowd names) are sanitized by the callers with :func:`simfab.io.outpaths.safe_name`.
"""

from __future__ import annotations

import os

from simfab.crowd.bracket import plot_brackets, strength_scores
from simfab.crowd.plots import plot_expert_network, plot_method_errors, plot_study
from simfab.io.atomic import write_csv, write_json


def aggregate_outputs(ratings, truth, result: dict, out: str, *, title: str = "crowd") -> dict:
    """Write the aggregate table, rater table, summary JSON and (with truth) figures."""

    os.makedirs(out, exist_ok=True)
    methods = result["methods"]
    names = list(methods)
    bayes = result["bayes"]
    header = ["task"] + names + ["bayesian_lo", "bayesian_hi"] + (["truth"] if truth is not None else [])
    rows = []
    for j, t in enumerate(ratings.tasks):
        lo, hi = bayes["x_interval"][t]
        rows.append([t] + [methods[n]["estimates"][t] for n in names] + [lo, hi]
                    + ([float(truth[j])] if truth is not None else []))
    outputs = {"aggregates_csv": str(write_csv(os.path.join(out, "aggregates.csv"), header, rows))}
    rrows = []
    indiv = result.get("individual_errors", {})
    for w in ratings.workers:
        a = bayes["alpha"][w]
        rrows.append([w, a["mean"], a["interval"][0], a["interval"][1], indiv.get(w, "")])
    outputs["raters_csv"] = str(write_csv(os.path.join(out, "raters.csv"),
                                          ["worker", "alpha_mean", "alpha_lo", "alpha_hi", "rms_error"], rrows))
    if truth is not None:
        sc = ratings.scale
        crowd_err = methods["bayesian"]["rms_continuous"]
        ind = [indiv[w] for w in ratings.workers]
        outputs["expert_network_png"] = plot_expert_network(
            crowd_err, ind, ratings.workers, os.path.join(out, "expert_network.png"),
            title=f"{title}: Bayesian crowd estimate vs individuals")
        per_q = {n: abs(sc.to_unit([methods[n]["estimates"][t] for t in ratings.tasks]) - sc.to_unit(truth))
                 for n in names}
        outputs["errors_png"] = plot_method_errors(per_q, ratings.tasks, os.path.join(out, "errors_per_question.png"),
                                                   title=f"{title}: crowd error per question")
    outputs["summary_json"] = os.path.join(out, "summary.json")
    summary = dict(result, outputs=outputs, tasks=list(ratings.tasks), workers=len(ratings.workers),
                   scale=[ratings.scale.lo, ratings.scale.hi])
    write_json(outputs["summary_json"], summary)
    return summary


def study_outputs(result, out: str, *, title: str) -> dict:

    rows = result.rows()
    outputs = {
        "study_csv": str(write_csv(os.path.join(out, "study.csv"), list(rows[0]), [list(r.values()) for r in rows])),
        "study_png": plot_study(result, os.path.join(out, "study.png"), title=title),
    }
    summary = {"sizes": rows, "seconds": result.seconds, "outputs": outputs}
    outputs["study_json"] = str(write_json(os.path.join(out, "study.json"), summary))
    return summary


def truth_outputs(rows, out: str, *, scale, notes=()) -> dict:

    cols = ["orientation", "rx_deg", "ry_deg", "rz_deg", "support_volume_m3", "overhang_area_m2", "raycast_volume_m3",
            "raycast_rel_diff", "support_score", "finish_score"]
    table = [[r["orientation"], *r["euler_deg"], r["support_volume"], r["overhang_area"], r.get("raycast_volume", ""),
              r.get("raycast_rel_diff", ""), r["support_score"], r["finish_score"]] for r in rows]
    outputs = {
        "table_csv": str(write_csv(os.path.join(out, "truth_table.csv"), cols, table)),
        "support_truth_csv": str(write_csv(os.path.join(out, "truth_support.csv"), ["task", "truth"],
                                           [[r["orientation"], r["support_score"]] for r in rows])),
        "finish_truth_csv": str(write_csv(os.path.join(out, "truth_finish.csv"), ["task", "truth"],
                                          [[r["orientation"], r["finish_score"]] for r in rows])),
    }
    summary = {"orientations": rows, "scale": list(scale), "mesh_notes": list(notes), "outputs": outputs}
    outputs["truth_json"] = str(write_json(os.path.join(out, "truth.json"), summary))
    return summary


def bracket_outputs(results, setup, out: str) -> dict:
    """Tables, truth CSV, picture and JSON of a bracket survey."""
    import dataclasses

    scores = strength_scores(results)
    rows = [[r.name, r.deflection, r.area, r.n_triangles, r.newton_iterations, float(s)]
            for r, s in zip(results, scores)]
    outputs = {
        "table_csv": str(write_csv(os.path.join(out, "brackets.csv"), ["design", "tip_deflection_m", "area_m2",
                                                                       "triangles", "newton_iterations",
                                                                       "strength_score"], rows)),
        "truth_csv": str(write_csv(os.path.join(out, "truth_strength.csv"), ["task", "truth"],
                                   [[r.name, float(s)] for r, s in zip(results, scores)])),
        "designs_png": plot_brackets(results, scores, os.path.join(out, "brackets.png")),
    }
    summary = {
        "setup": dataclasses.asdict(setup),
        "designs": {r.name: {"tip_deflection": r.deflection, "score": float(s), "area": r.area}
                    for r, s in zip(results, scores)},
        "outputs": outputs,
    }
    outputs["summary_json"] = str(write_json(os.path.join(out, "brackets.json"), summary))
    return summary


def synth_outputs(crowd, out: str) -> dict:
    """ratings.csv, truth.csv and planted.json (planted expertise, difficulty, malicious raters) of a
    synthetic crowd (:class:`simfab.crowd.synth.SyntheticCrowd`); returns label -> path."""
    os.makedirs(out, exist_ok=True)
    r = crowd.ratings
    outputs = {
        "ratings_csv": str(write_csv(os.path.join(out, "ratings.csv"), ["worker", "task", "label"], r.to_long())),
        "truth_csv": str(write_csv(os.path.join(out, "truth.csv"), ["task", "truth"],
                                   list(zip(r.tasks, crowd.truth.tolist())))),
    }
    planted = {"alpha": dict(zip(r.workers, crowd.alpha.tolist())),
               "malicious": [w for w, b in zip(r.workers, crowd.malicious) if b],
               "beta": dict(zip(r.tasks, crowd.beta.tolist())), "truth": dict(zip(r.tasks, crowd.truth.tolist()))}
    outputs["planted_json"] = str(write_json(os.path.join(out, "planted.json"), planted))
    return outputs
