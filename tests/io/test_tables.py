"""The scene-table loader (simfab.io.tables): unknown keys and refused values name the file, the
table and the key, or the flag a value came from; types follow the config's annotations; a config
nested like its TOML loads table by table."""

from dataclasses import dataclass

import pytest

from simfab.errors import InputError
from simfab.io.tables import FieldError, Override, flag_overrides, load_nested, load_table


@dataclass(frozen=True, kw_only=True)
class Colonize:
    influence: float = 0.02
    kill: float = 0.005
    steps: int | None = None

    def __post_init__(self):
        if not self.kill > 0:
            raise FieldError(f"kill={self.kill!r} must be positive", key="kill", where="[colonize]",
                             flag_message=f"must be positive, got {self.kill!r}")
        if not self.influence > self.kill:  # a check across keys, blamed on kill
            raise FieldError(f"influence {self.influence} must exceed kill {self.kill}", key="kill",
                             where="[colonize]")


@dataclass(frozen=True, kw_only=True)
class Skin:
    radius: float = 0.002


@dataclass(frozen=True, kw_only=True)
class Growth:
    colonize: Colonize
    skin: Skin
    seed: int = 0

    def __post_init__(self):
        if self.skin.radius > self.colonize.kill:  # a check across tables
            raise FieldError(f"skin radius {self.skin.radius} must not exceed kill {self.colonize.kill}",
                             key="skin.radius", where="[skin] radius")


def test_unknown_keys_and_types_name_file_table_and_key():
    with pytest.raises(InputError) as e:
        load_table(Colonize, {"influense": 0.1}, table_name="colonize", file="g.toml")
    assert str(e.value) == "g.toml: [colonize]: unknown key 'influense' (known: influence, kill, steps)"
    with pytest.raises(InputError) as e:
        load_table(Colonize, {"steps": 2.5}, table_name="colonize", file="g.toml")
    assert str(e.value).startswith("g.toml: [colonize]: steps=2.5 must be of type `int | null`")
    with pytest.raises(InputError, match="must be a table"):
        load_table(Colonize, 3, table_name="colonize", file="g.toml")
    c = load_table(Colonize, {"influence": 1, "steps": 4}, table_name="colonize", file="g.toml")
    assert isinstance(c.influence, float) and c.influence == 1.0 and c.steps == 4


def test_a_value_is_blamed_where_it_came_from():
    table = {"influence": 0.02, "kill": 0.004}
    with pytest.raises(InputError) as e:  # from the file
        load_table(Colonize, {"kill": -1.0}, table_name="colonize", file="g.toml")
    assert str(e.value) == "g.toml: [colonize]: kill=-1.0 must be positive"
    with pytest.raises(InputError) as e:  # from a flag
        load_table(Colonize, table, table_name="colonize", file="g.toml", overrides=flag_overrides({"kill": -1.0}))
    assert str(e.value) == "--kill: must be positive, got -1.0"
    with pytest.raises(InputError) as e:  # a check across keys: the flag's value is the one blamed
        load_table(Colonize, table, table_name="colonize", file="g.toml", overrides={"kill": Override(0.1, "--kill")})
    assert str(e.value) == "--kill: influence 0.02 must exceed kill 0.1"
    notes = []
    c = load_table(Colonize, table, table_name="colonize", file="/x/g.toml", log=notes.append,
                   overrides={"kill": Override(0.003, "--kill"), "steps": None})
    assert c.kill == 0.003 and notes == ["--kill 0.003 overrides g.toml [colonize] kill = 0.004"]
    c = load_table(Colonize, {"steps": 3}, table_name="colonize", overrides={"steps": None})
    assert c.steps is None  # None removes the key: its default


def test_parsers_run_before_the_type_check():
    def pair(v, where):
        if not (isinstance(v, list) and len(v) == 2):
            raise InputError(f"must be a pair, got {v!r}", where=where)
        return float(v[0])

    assert load_table(Skin, {"radius": [1, 2]}, table_name="skin", parsers={"radius": pair}).radius == 1.0
    with pytest.raises(InputError) as e:
        load_table(Skin, {"radius": 3}, table_name="skin", file="g.toml", parsers={"radius": pair})
    assert str(e.value) == "g.toml: [skin] radius: must be a pair, got 3"


def test_a_config_nested_like_its_toml():
    doc = {"colonize": {"kill": 0.004}, "skin": {"radius": 0.001}, "seed": 3}
    g = load_nested(Growth, doc, file="g.toml")
    assert g.colonize.kill == 0.004 and g.skin.radius == 0.001 and g.seed == 3
    with pytest.raises(InputError) as e:
        load_nested(Growth, {**doc, "colonise": {}}, file="g.toml")
    assert str(e.value).startswith("g.toml: unknown table [colonise]")
    with pytest.raises(InputError) as e:  # across tables, the file's value
        load_nested(Growth, {**doc, "skin": {"radius": 0.01}}, file="g.toml")
    assert str(e.value) == "g.toml: [skin] radius: skin radius 0.01 must not exceed kill 0.004"
    with pytest.raises(InputError) as e:  # across tables, a flag's value
        load_nested(Growth, doc, file="g.toml", overrides={"skin": {"radius": Override(0.01, "--skin-radius")}})
    assert str(e.value) == "--skin-radius: skin radius 0.01 must not exceed kill 0.004"
    with pytest.raises(InputError) as e:  # within a table
        load_nested(Growth, doc, file="g.toml", overrides={"colonize": flag_overrides({"kill": 0})})
    assert str(e.value) == "--kill: must be positive, got 0.0"
