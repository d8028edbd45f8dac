"""The one rule for a file a user names (`legcal_bench.files.packaged`): a path from the
working directory, else a file the package ships by its name; examples that need the
external models in ../shared say so when they are absent."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from legcal_bench.errors import ConfigError, MissingModelError
from legcal_bench.files import packaged as pk
from legcal_bench.robots import load_robot

REPO = Path(__file__).resolve().parents[1]


def test_every_kind_of_file_resolves_from_any_folder(tmp_path, monkeypatch):
    from legcal_bench.policies.spec import load_policy_spec
    from legcal_bench.policies.zmp_walker import load_teacher_recipe

    monkeypatch.chdir(tmp_path)  # not a checkout
    assert load_robot("examples/unitree_g1.legmap.yaml").name == "unitree_g1"
    assert load_policy_spec("examples/unitree_g1.policy.yaml").model_file.is_file()  # the G1's published policy
    assert load_policy_spec("a3").model_file.is_file()  # our shipped walker, by name
    assert load_teacher_recipe("a3") is not None  # the A3-like robot's teacher recipe, by name
    with pytest.raises(ConfigError, match="no such file"):
        load_policy_spec("examples/none.policy.yaml")


def test_a_file_in_the_working_directory_comes_before_the_shipped_one(tmp_path, monkeypatch):
    from legcal_bench.policies.spec import load_policy_spec

    monkeypatch.chdir(tmp_path)
    (tmp_path / "examples").mkdir()
    (tmp_path / "examples" / "unitree_g1.policy.yaml").write_text("not: a spec\n")
    with pytest.raises(ConfigError, match=r"examples/unitree_g1.policy.yaml"):
        load_policy_spec("examples/unitree_g1.policy.yaml")
    assert pk.packaged("a3", {"a3": tmp_path / "missing"}) == Path("a3")  # a missing shipped file is not taken


def test_an_example_whose_external_model_is_absent_says_where_it_should_be(tmp_path, monkeypatch):
    from legcal_bench.policies.spec import load_policy_spec

    installed = tmp_path / "site" / "legcal_bench" / "examples"  # as in a wheel: no ../shared beside it
    installed.mkdir(parents=True)
    for name in ("unitree_g1.legmap.yaml", "unitree_g1.policy.yaml"):
        shutil.copy(REPO / "examples" / name, installed / name)
    monkeypatch.setattr(pk, "examples_dir", lambda: installed)
    monkeypatch.chdir(tmp_path)
    with pytest.raises(MissingModelError, match=r"field 'mjcf' .*this example points into \.\./shared/external"):
        load_robot("examples/unitree_g1.legmap.yaml")
    with pytest.raises(ConfigError, match=r"model.file .*this example points into \.\./shared/external"):
        load_policy_spec("examples/unitree_g1.policy.yaml")
