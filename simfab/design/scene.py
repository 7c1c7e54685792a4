"""Design scenes: a coupling scene (:mod:`simfab.coupling.scene`) whose TOML has a ``[design]``
table (:class:`simfab.design.brief.DesignConfig`). Box sites named in ``keep`` mark regions of the
part that must stay unchanged (inactive handles), as the fixed support does."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from simfab.coupling.model import CouplingModel
from simfab.coupling.scene import check_turned_about_z, load_coupling_scene, read_scene_toml, scene_paths
from simfab.design.brief import DesignConfig, TargetProfile, read_target_profile
from simfab.errors import InputError
from simfab.io.mjcf import load_mjcf
from simfab.progress import log


@dataclass(frozen=True, kw_only=True, eq=False)
class DesignScene:
    """cm: the initial CouplingModel; brief; kept_regions: vertex arrays of the keep sites;
    target: TargetProfile or None; xml, toml: the scene's files."""

    cm: CouplingModel
    brief: DesignConfig
    kept_regions: tuple
    target: TargetProfile | None
    xml: Path
    toml: Path


def check_brief_table(scene) -> None:
    """Validate the ``[design]`` table of a coupling scene's TOML, when it has one (InputError naming
    the file, the table and the key): commands that only simulate the scene check it too, so a
    misspelt brief key is reported by every command, not first by ``couple optimize``."""
    _, toml = scene_paths(scene)
    table = read_scene_toml(toml).get("design")
    if table is None:
        return
    if not isinstance(table, dict):
        raise InputError("[design] must be a table", where=str(toml))
    DesignConfig.from_dict(dict(table), where=f"{toml} [design]")


def load_design_scene(scene, *, design: dict | None = None, simulation: dict | None = None,
                      contact: dict | None = None, device: str = "cpu", quiet: bool = True) -> DesignScene:
    """Load a coupling scene with its design brief; ``design`` overrides keys of ``[design]``
    (command-line options), ``simulation`` those of ``[simulation]``, ``contact`` those of ``[contact]``
    (values or :class:`simfab.io.tables.Override` naming their flag); ``quiet``: do not log the flags
    that replace values of the scene file."""
    xml, toml = scene_paths(scene)
    if not xml.is_file():
        raise InputError("scene file not found", where=str(xml))
    cfg = read_scene_toml(toml)
    table = cfg.get("design", {})
    if not isinstance(table, dict):
        raise InputError("[design] must be a table", where=str(toml))
    notes = []  # flags that replace values of [design]: logged once the scene is loaded
    brief = DesignConfig.from_dict(dict(table), where=f"{toml} [design]", log=notes.append,
                                  overrides={k: v for k, v in (design or {}).items() if v is not None})
    cm = load_coupling_scene(xml, overrides={"simulation": simulation or {}, "contact": contact or {}}, device=device,
                             quiet=quiet)
    target = None
    if brief.target_profile:
        p = Path(brief.target_profile)
        if not p.is_absolute() and not (design or {}).get("target_profile"):
            p = toml.parent / p
        s, f = read_target_profile(p)
        target = TargetProfile(s=s, force=f, source=str(p))
    regions = []
    if brief.keep:
        sc = load_mjcf(xml)
        for name in brief.keep:
            if name not in sc.sites:
                raise InputError(f"no site named {name!r} (a region to keep unchanged)", where=f"{toml} [design] keep")
            if cm.dim == 2:
                check_turned_about_z(sc, name, where=f"{xml} site {name!r}")
            inside = np.flatnonzero(sc.in_box(name, cm.fem.rest))
            if inside.size == 0:
                raise InputError(f"site {name!r} contains no vertex of the part", where=f"{toml} [design] keep")
            regions.append(inside)
    for note in notes:
        log(note, quiet=quiet)
    return DesignScene(cm=cm, brief=brief, kept_regions=tuple(regions), target=target, xml=xml, toml=toml)
