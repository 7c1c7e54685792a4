"""The bundled 3D-printing survey (``scenes/crowd/printing_survey.toml`` + ``.xml``).

A bracket-like part (base plate with a hole, an upright pierced by a horizontal hole, a
cantilevered arm) is shown in six orientations; raters judge the support material each
needs on a 1..10 scale. The truth is computed from the mesh (support volume, scaled
linearly to 1..10); responses are synthetic, drawn from the expertise/difficulty model
for 15 practitioners and 100 members of the general public (10 % malicious).

``python scenes/crowd/make_survey.py`` (or :func:`make_bundle`) regenerates the mesh, the
MJCF picture of the six orientations, the truth and the two response files from the TOML.
"""

from __future__ import annotations

import dataclasses
import os
import tomllib
from pathlib import Path

import numpy as np

from simfab._bundled import scenes_dir
from simfab.crowd import synth
from simfab.crowd.analysis import aggregate_all
from simfab.crowd.config import CrowdMix
from simfab.crowd.data import Scale, load_ratings, load_truth
from simfab.crowd.microcrowd import micro_crowd_study
from simfab.crowd.outputs import aggregate_outputs, study_outputs, truth_outputs
from simfab.crowd.truth import orientation_table, parse_orientations
from simfab.errors import InputError
from simfab.io.atomic import write_csv
from simfab.io.mesh import load_mesh, save_mesh
from simfab.io.mjcf import MJCFBuilder
from simfab.io.outpaths import safe_name
from simfab.io.render import render_mjcf
from simfab.progress import log

SURVEY_DIR = scenes_dir("crowd")
SURVEY_TOML = SURVEY_DIR / "printing_survey.toml"


@dataclasses.dataclass(frozen=True, kw_only=True)
class CrowdConfig:
    name: str
    mix: CrowdMix
    file: str  #: ratings CSV, relative to the TOML


@dataclasses.dataclass(frozen=True, kw_only=True)
class SurveyConfig:
    """A survey scene. Paths are relative to the TOML's folder (``root``)."""

    root: Path
    title: str
    mesh: str
    units: str
    question: str  #: "support" (more volume = higher) or "finish" (10 = least overhang)
    orientations: tuple[str, ...]
    scale: tuple[float, float]
    difficulty: tuple[float, ...]  #: beta per question for the synthetic responses
    seed: int
    truth_file: str
    picture: str  #: MJCF showing the part in every orientation
    crowds: tuple[CrowdConfig, ...]
    demo_subcrowds: int

    @property
    def truth_key(self) -> str:
        """The orientation-table column (:func:`survey_truth`) that is this survey's truth."""
        return "support_score" if self.question == "support" else "finish_score"


def load_survey(path=SURVEY_TOML) -> SurveyConfig:
    """Read and validate a survey TOML (InputError naming the field on problems)."""
    path = Path(path)
    if not path.is_file():
        raise InputError("survey file not found", where=str(path))
    try:
        d = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as e:
        raise InputError(f"not valid TOML ({e})", where=str(path)) from None

    def get(table, key, kind, where):
        if key not in table:
            raise InputError(f"missing field {where}.{key}", where=str(path))
        v = table[key]
        if kind is float and isinstance(v, int):
            v = float(v)
        if not isinstance(v, kind):
            raise InputError(f"field {where}.{key} must be {kind.__name__}, got {v!r}", where=str(path))
        return v

    s = d.get("survey", {})
    question = get(s, "question", str, "survey")
    if question not in ("support", "finish"):
        raise InputError(f"survey.question must be 'support' or 'finish', got {question!r}", where=str(path))
    crowds = []
    for name, c in d.get("crowds", {}).items():
        w = f"crowds.{name}"
        mix = CrowdMix(
            size=get(c, "size", int, w), alpha_mean=get(c, "alpha_mean", float, w),
            alpha_sd=get(c, "alpha_sd", float, w),
            malicious_fraction=float(c.get("malicious_fraction", 0.0)),
        )
        crowds.append(CrowdConfig(name=name, mix=mix, file=get(c, "file", str, w)))
    if not crowds:
        raise InputError("no [crowds.*] tables", where=str(path))
    scale = get(s, "scale", list, "survey")
    diff = get(s, "difficulty", list, "survey")
    return SurveyConfig(
        root=path.parent, title=get(s, "title", str, "survey"), mesh=get(s, "mesh", str, "survey"),
        units=get(s, "units", str, "survey"), question=question,
        orientations=tuple(get(s, "orientations", list, "survey")), scale=(float(scale[0]), float(scale[1])),
        difficulty=tuple(float(v) for v in diff), seed=get(s, "seed", int, "survey"),
        truth_file=get(s, "truth", str, "survey"), picture=get(s, "picture", str, "survey"), crowds=tuple(crowds),
        demo_subcrowds=int(d.get("demo", {}).get("subcrowds", 30)),
    )


def build_part_mm():
    """The survey part, millimetres: (vertices (n, 3), faces (m, 3)), watertight.

    Base plate 60 x 40 x 8 with a vertical hole (r 6), an upright 8 x 40 x 50 with a
    horizontal hole (r 9) along y... through x, and an arm 8 mm thick cantilevered 37 mm
    from the top of the upright over the base: overhangs in every orientation differ.
    """
    from manifold3d import Manifold

    base = Manifold.cube((60.0, 40.0, 8.0))
    upright = Manifold.cube((8.0, 40.0, 50.0))
    arm = Manifold.cube((37.0, 40.0, 8.0)).translate((8.0, 0.0, 42.0))
    hole_v = Manifold.cylinder(20.0, 6.0, 6.0, 48).translate((42.0, 20.0, -5.0))
    hole_h = Manifold.cylinder(20.0, 9.0, 9.0, 48).rotate((0.0, 90.0, 0.0)).translate((-5.0, 20.0, 27.0))
    part = (base + upright + arm) - hole_v - hole_h
    m = part.to_mesh()
    return np.asarray(m.vert_properties, float)[:, :3], np.asarray(m.tri_verts, np.int64)


def survey_truth(spec: SurveyConfig, *, raycast: bool = True) -> list[dict]:
    """Orientation table of the survey's mesh (see :func:`simfab.crowd.truth.orientation_table`)."""

    mesh = load_mesh(spec.root / spec.mesh, units=spec.units, require_watertight=True)
    return orientation_table(mesh.vertices, mesh.faces, parse_orientations(spec.orientations), raycast=raycast,
                             scale=spec.scale)


def _picture(spec: SurveyConfig, vertices_m, faces, path):
    """MJCF with the part once per orientation, side by side on the build plate."""
    from scipy.spatial.transform import Rotation


    b = MJCFBuilder("printing_survey")
    b.mesh_asset("part", vertices_m, faces)
    b.add(b.worldbody, "light", pos=(0.0, -0.3, 0.6), dir=(0, 0.4, -1), diffuse=(0.8, 0.8, 0.8))
    gap = 0.03
    placed, x, depth = [], 0.0, 0.0
    for o in parse_orientations(spec.orientations):
        R = o.matrix
        v = vertices_m @ R.T
        lo, hi = v.min(0), v.max(0)
        placed.append((o, R, lo, hi, x))
        x += (hi[0] - lo[0]) + gap
        depth = max(depth, hi[1] - lo[1])
    x0 = 0.5 * (x - gap)  # centre the row on the origin
    b.geom(b.worldbody, type="plane", size=(x0 + gap, depth / 2 + gap, 0.01), rgba=(0.85, 0.85, 0.88, 1))
    for o, R, lo, hi, xo in placed:
        q = Rotation.from_matrix(R).as_quat()  # x, y, z, w
        body = b.body(f"o_{o.name}", pos=(xo - x0 - lo[0], -0.5 * (lo[1] + hi[1]), -lo[2]),
                      quat=(q[3], q[0], q[1], q[2]))
        b.geom(body, type="mesh", mesh="part", rgba=(0.2, 0.45, 0.8, 1), contype=0, conaffinity=0)
    b.save(path)


def make_bundle(spec: SurveyConfig | None = None) -> dict:
    """(Re)generate mesh, picture, truth and synthetic responses of a survey from its TOML."""

    spec = spec or load_survey()
    import trimesh

    V, F = build_part_mm()
    save_mesh(trimesh.Trimesh(V, F, process=False), spec.root / spec.mesh)
    rows = survey_truth(spec)
    truth = np.array([r[spec.truth_key] for r in rows])
    tasks = [r["orientation"] for r in rows]
    write_csv(spec.root / spec.truth_file, ["task", "truth"], list(zip(tasks, truth.tolist())))
    _picture(spec, V * 1e-3 if spec.units == "mm" else V, F, spec.root / spec.picture)
    scale = Scale(lo=spec.scale[0], hi=spec.scale[1])
    if len(spec.difficulty) not in (1, len(tasks)):
        raise InputError(f"survey.difficulty needs 1 or {len(tasks)} values", where=str(spec.root))
    for k, c in enumerate(spec.crowds):
        crowd = synth.simulate_crowd(c.mix, scale=scale, truth=truth, beta=np.resize(spec.difficulty, len(tasks)),
                               seed=spec.seed + k, worker_prefix=f"{c.name[:2]}")
        r = dataclasses.replace(crowd.ratings, tasks=tuple(tasks))
        write_csv(spec.root / c.file, ["worker", "task", "label"], r.to_long())
    return {"tasks": tasks, "truth": truth.tolist()}


def run_bundled_survey(*, out: str, seed: int = 0, quiet: bool = True, spec: SurveyConfig | None = None,
                       subcrowds: int | None = None) -> dict:
    """The demo: recompute the truth from the mesh, aggregate each crowd, expert network,
    a micro-crowd study of the practitioners, a picture of the six orientations."""

    spec = spec or load_survey()
    scale = Scale(lo=spec.scale[0], hi=spec.scale[1])
    log("crowd demo: ground truth from the mesh (support volume per orientation)", quiet=quiet)
    rows = survey_truth(spec)
    summary = {"survey": spec.title, "truth": truth_outputs(rows, os.path.join(out, "truth"), scale=spec.scale)}
    bundled = {r["orientation"]: r[spec.truth_key] for r in rows}
    crowds = {}
    for c in spec.crowds:
        ratings = load_ratings(spec.root / c.file, scale)
        truth = load_truth(spec.root / spec.truth_file, ratings)
        drift = max(abs(bundled[t] - v) for t, v in zip(ratings.tasks, truth))
        if drift > 1e-6:
            raise InputError(f"bundled truth differs from the mesh's by {drift:.3g}; rerun scenes/crowd/make_survey.py",
                             where=str(spec.root / spec.truth_file))
        log(f"crowd demo: aggregating {c.name} ({len(ratings.workers)} raters)", quiet=quiet)
        res = aggregate_all(ratings, truth, seed=seed, quiet=quiet)
        s = aggregate_outputs(ratings, truth, res, os.path.join(out, safe_name(c.name)),
                              title=f"{spec.title}, {c.name.replace('_', ' ')}")
        crowds[c.name] = {
            "rms": {m: v["rms"] for m, v in s["methods"].items()},
            "percentile": {m: v["percentile"] for m, v in s["methods"].items()},
            "bayes": {k: s["bayes"][k] for k in ("rhat_max", "ess_min", "seconds", "converged")},
            "warnings": s["warnings"],
            "outputs": s["outputs"],
        }
        if c.name == spec.crowds[0].name:
            n_sub = subcrowds or spec.demo_subcrowds
            log(f"crowd demo: micro-crowd study of {c.name} ({n_sub} sub-crowds per size)", quiet=quiet)
            st = micro_crowd_study(ratings, truth, n_sub=n_sub, seed=seed, quiet=quiet)
            crowds[c.name]["study"] = study_outputs(st, os.path.join(out, safe_name(c.name)),
                                                    title=f"{spec.title}, {c.name}")
    summary["crowds"] = crowds
    try:

        summary["picture_png"] = str(render_mjcf(spec.root / spec.picture, os.path.join(out, "orientations.png"),
                                                 width=960, height=360))
    except Exception as e:  # a picture is a nicety; never fail the demo over OpenGL
        log(f"crowd demo: could not render the orientations ({type(e).__name__}: {e})", quiet=quiet)
    return summary
